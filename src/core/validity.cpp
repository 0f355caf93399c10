// model_validity: each model a frame uses, checked against the domain where it holds (validity.h).
// The figures and their sources are stated next to each check; README.md ("Where the models hold")
// repeats them for readers of meta.json.
#include "vksonar/validity.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "core/angles.h"
#include "core/plan.h"

namespace vksonar {
namespace {

std::string fmt(double v) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.4g", v);
    return buf;
}

// One interval check of a model: the first key outside its interval decides the model's entry.
struct Interval {
    const char* key;
    double value;
    double lo, hi;
    const char* unit;
};

std::string interval_text(const Interval& i) {
    return std::string(i.key) + " in [" + fmt(i.lo) + ", " + fmt(i.hi) + "]" + (*i.unit ? " " : "") + i.unit;
}

// Francois & Garrison, JASA 72(3) 896 and 72(6) 1879 (1982): the total-absorption equation is stated
// for 200 Hz to 1 MHz and about 5 % accurate there. Its oceanographic limits, as the NPL technical
// guide "Calculation of absorption of sound in seawater" quotes them: where the MgSO4 term dominates
// (up to 500 kHz) -2 to 22 degC, 30 to 35 ppt, 0 to 3.5 km; above 500 kHz, where the pure-water term
// dominates, 0 to 30 degC, 0 to 40 ppt, 0 to 10 km. pH enters only the boric-acid term (below ~10 kHz);
// 7.7 to 8.3 is the span of ocean pH over which Ainslie & McColm (JASA 103(3) 1998) compared their
// simplified formula with it, used here for the lower band only.
ModelValidity francois_garrison(const SonarConfig& c) {
    const bool high = c.frequency_hz > 500e3;
    std::vector<Interval> checks = {{"frequency", c.frequency_hz, 200.0, 1e6, "Hz"}};
    if (high) {
        checks.push_back({"temperature", c.temperature_c, 0.0, 30.0, "degC"});
        checks.push_back({"salinity", c.salinity_ppt, 0.0, 40.0, "ppt"});
        checks.push_back({"water_depth", c.water_depth_m, 0.0, 10000.0, "m"});
    } else {
        checks.push_back({"temperature", c.temperature_c, -2.0, 22.0, "degC"});
        checks.push_back({"salinity", c.salinity_ppt, 30.0, 35.0, "ppt"});
        checks.push_back({"water_depth", c.water_depth_m, 0.0, 3500.0, "m"});
        checks.push_back({"ph", c.ph, 7.7, 8.3, ""});
    }
    std::string domain;
    for (const Interval& i : checks)
        domain += (domain.empty() ? "" : ", ") + interval_text(i);
    domain += high ? " (above 500 kHz)" : " (up to 500 kHz)";
    ModelValidity v{"francois_garrison", true, "frequency", c.frequency_hz, domain, "none"};
    for (const Interval& i : checks) {
        if (i.value >= i.lo && i.value <= i.hi) continue;
        v.ok = false;
        v.key = i.key;
        v.value = i.value;
        v.action = std::string(i.key) == "frequency" && i.value > i.hi
                       ? "extrapolates the fit: its pure-water f^2 term, which dominates there, is the classical "
                         "viscous law and still the best model available"
                       : "extrapolates the fit (about 5 % accurate inside its domain, unknown outside)";
        break;
    }
    return v;
}

// Beam patterns are far-field (Fraunhofer) patterns. A beamwidth theta (the configured -3 dB width, in
// radians) implies the aperture of a uniform line array, L = 0.886 lambda / theta; the pattern holds
// beyond about L^2 / lambda. (theta is the two-way width: the one-way width of the same array is up to
// sqrt(2) wider, so L and the distance are upper estimates: a warning errs on the safe side.)
// focus_modelled: beam_focus fixed or none, and a near kernel that applies it (plan_focus.cpp).
ModelValidity far_field(const SonarConfig& c, bool focus_modelled) {
    const double lambda = c.sound_speed_mps / c.frequency_hz;
    double aperture = 0.0;
    const char* which = "horizontal_beamwidth";
    // With beam_focus fixed or none the horizontal pattern is the aperture's at each range (plan_focus.cpp):
    // only the vertical aperture is left to the far-field rule.
    if (c.effects.horizontal_pattern != EffectMode::off && !focus_modelled)
        aperture = 0.886 * lambda / (c.horizontal_beamwidth_deg * kDegToRad);
    if (c.effects.vertical_pattern != EffectMode::off) {
        const double vertical = 0.886 * lambda / (c.vfov_deg * kDegToRad);
        if (vertical > aperture) {
            aperture = vertical;
            which = "vfov";
        }
    }
    const double distance = aperture * aperture / lambda;
    ModelValidity v{"far_field_beam_pattern",
                    c.range_min_m >= distance,
                    "range_min",
                    c.range_min_m,
                    "range_min >= L^2 / lambda = " + fmt(distance) + " m (aperture L = 0.886 lambda / " + which +
                        " = " + fmt(aperture) + " m, lambda = " + fmt(lambda) + " m)",
                    "none"};
    if (!v.ok)
        v.action =
            "uses the far-field pattern at every range: nearer than " + fmt(distance) +
            " m an unfocused array's beam is wider than modelled (a focusing or lens sonar's is not)" +
            std::string(std::string(which) == "horizontal_beamwidth" && c.mode == SonarMode::physical &&
                                (c.horizontal_pattern == BeamPattern::sinc || c.horizontal_pattern == BeamPattern::hann)
                            ? "; set beam_focus none (unfocused) or fixed with focus_range (a lens) to model it"
                            : "");
    return v;
}

// Chebyshev patterns use the large-array limit of Dolph-Chebyshev: an N-element array's
// T_{N-1}(cosh(A / (N-1)) cos(u)) becomes cos(sqrt(x^2 - A^2)) through acosh(1 + e) ~ sqrt(2 e), which
// errs by about e / 12 (1 % at A / (N-1) = 0.5). N is estimated from the beamwidth as a half-wavelength
// spaced array of the uniform aperture above: N = 2 L / lambda = 1.772 / theta (a Chebyshev taper
// widens the beam, so the real N is larger and this errs on the safe side). Domain: N - 1 >= 2 A.
ModelValidity chebyshev(const char* key, double beamwidth_deg, double sidelobe_db) {
    const double elements = 1.772 / (beamwidth_deg * kDegToRad);
    const double a = std::acosh(std::pow(10.0, -sidelobe_db / 20.0));
    const double needed = 1.0 + 2.0 * a;
    ModelValidity v{"chebyshev_large_array",
                    elements >= needed,
                    key,
                    beamwidth_deg,
                    "about N = 1.772 / " + std::string(key) + " = " + fmt(elements) +
                        " half-wavelength elements >= 1 + 2 acosh(10^(-sidelobe_db/20)) = " + fmt(needed) +
                        " (side lobes " + fmt(sidelobe_db) + " dB)",
                    "none"};
    if (!v.ok)
        v.action = "uses the large-array pattern: an array of about " + fmt(elements) +
                   " elements has a wider main lobe and uneven side lobes";
    return v;
}

// The rough model's facet term is the Kirchhoff (tangent-plane) approximation in its geometric-optics
// form, without shadowing or multiple scattering. Both stay small near the specular direction while
// the rms slope is below about 0.5 (27 deg), a common rule of thumb; validate() already refuses slopes
// past 1 (45 deg). Grazing angles below about 2 atan(m), where shadowing grows, depend on the scene
// and are not checked per pixel.
ModelValidity rough_facet(std::size_t index, const AcousticMaterial& m) {
    constexpr double kMaxSlope = 0.5;
    ModelValidity v{"rough_facet",
                    m.rms_slope <= kMaxSlope,
                    "material " + std::to_string(index) + " '" + m.name + "' rms_slope",
                    m.rms_slope,
                    "rms_slope <= " + fmt(kMaxSlope) + " (and grazing angles above about 2 atan(rms_slope); not " +
                        "checked per pixel)",
                    "none"};
    if (!v.ok) v.action = "uses the single-scattering facet term without shadowing or multiple scattering";
    return v;
}

// The near kernel as beam_sampling judges it: whether it weighs each column by the pattern, and its reach
// in the separation unit (angle, or sine for a line array).
struct NearKernel {
    bool per_column = false;
    double reach_units = 0.0;
};

// With the horizontal pattern on and a kernel that reaches past the next beam, the beamform stage weighs
// each profile column by the pattern at its own direction (the near kernel, docs/pipeline.md §4): a target
// between two beams reads what the pattern says, as long as the kernel reaches it (half the widest gap).
// Otherwise (the pattern off, or a kernel shorter than the beam spacing: K = 0) the scan is the columns
// resampled onto their two nearest beams (a tent), so between beam centres the response is interpolated
// linearly. Either holds while the beams sample the main lobe: adjacent beams at most a beamwidth apart
// (in sine for a line array, whose beams are equally wide there). Beams two beamwidths apart read a target
// midway between them 3 dB down in both with the tent, where the pattern says 18 dB. kernel: the plan's,
// or null to judge it from the config (plan.cpp's K >= 1 from the nearest gap, before the main-lobe-only
// rule).
ModelValidity beam_sampling(const SonarConfig& c, const NearKernel* kernel) {
    const bool line_array = resolves_to_line_array(c, nullptr);
    const auto table = beam_table(c);
    double widest = 0.0, nearest = std::numeric_limits<double>::infinity();
    if (table)
        for (std::size_t j = 1; j < table.value().size(); ++j) {
            const double a = table.value()[j - 1], b = table.value()[j];
            const double gap = line_array ? std::sin(a) - std::sin(b) : a - b;
            widest = std::max(widest, gap);
            nearest = std::min(nearest, gap);
        }
    NearKernel from_config;
    if (kernel == nullptr) {
        from_config.reach_units =
            sidelobe_reach_units(line_array, c.sidelobe_kernel_beamwidths * c.horizontal_beamwidth_deg * kDegToRad);
        from_config.per_column = c.effects.horizontal_pattern != EffectMode::off && from_config.reach_units >= nearest;
        kernel = &from_config;
    }
    const bool per_column = kernel->per_column;
    const double beamwidth = c.horizontal_beamwidth_deg * kDegToRad;
    const double widest_deg = widest / kDegToRad;
    ModelValidity v{"beam_sampling",
                    widest <= beamwidth * (1.0 + 1e-9) || (per_column && kernel->reach_units >= 0.5 * widest),
                    "beams",
                    double(table ? table.value().size() : c.beams),
                    "adjacent beams at most horizontal_beamwidth = " + fmt(c.horizontal_beamwidth_deg) + " deg apart" +
                        (line_array ? " in sine" : "") +
                        ", or the horizontal pattern applied per column (effects.horizontal_pattern not off) by a "
                        "kernel reaching half the widest gap; the widest gap is " +
                        fmt(widest_deg) + " deg",
                    "none"};
    if (!v.ok)
        v.action = per_column ? "applies the pattern per column only within the side-lobe kernel's reach: a target "
                                "midway between the two furthest-apart beams is past it (lengthen "
                                "accuracy.sidelobe_kernel_beamwidths, add beams or widen the beam)"
                              : "interpolates each beam's response linearly between beam centres: a target between "
                                "two beams reads up to 3 dB down in both where the pattern puts it lower (turn "
                                "effects.horizontal_pattern on, add beams or widen the beam)";
    return v;
}

std::vector<ModelValidity> model_validity(const SonarConfig& c, const std::vector<AcousticMaterial>& materials,
                                          const NearKernel* kernel) {
    std::vector<ModelValidity> out;
    if (c.absorption_db_per_m < 0.0 && c.effects.absorption != EffectMode::off) out.push_back(francois_garrison(c));
    if (c.effects.vertical_pattern != EffectMode::off || c.effects.horizontal_pattern != EffectMode::off)
        out.push_back(far_field(c, c.beam_focus != BeamFocus::dynamic && (kernel == nullptr || kernel->per_column)));
    if (c.mode == SonarMode::physical && c.beams > 1) out.push_back(beam_sampling(c, kernel));
    if (c.vertical_pattern == BeamPattern::chebyshev && c.effects.vertical_pattern != EffectMode::off)
        out.push_back(chebyshev("vfov", c.vfov_deg, c.vertical_sidelobe_db));
    if (c.horizontal_pattern == BeamPattern::chebyshev && c.effects.horizontal_pattern != EffectMode::off)
        out.push_back(chebyshev("horizontal_beamwidth", c.horizontal_beamwidth_deg, c.horizontal_sidelobe_db));
    if (c.effects.incidence != EffectMode::off)
        for (std::size_t i = 0; i < materials.size(); ++i)
            if (materials[i].model == AcousticMaterial::Model::rough) out.push_back(rough_facet(i, materials[i]));
    return out;
}

} // namespace

std::string ModelValidity::warning() const {
    std::string text =
        model + ": " + key + " = " + fmt(value) + " is outside the model's domain (" + domain + "); vksonar " + action;
    return detail::escape_control_chars(std::move(text)); // one line, whatever a material's name holds
}

std::vector<ModelValidity> model_validity(const SonarConfig& c, const std::vector<AcousticMaterial>& materials) {
    return model_validity(c, materials, nullptr);
}

std::vector<ModelValidity> model_validity(const SonarConfig& c, const std::vector<AcousticMaterial>& materials,
                                          bool near_kernel, double near_reach_units) {
    const NearKernel kernel{near_kernel, near_reach_units};
    return model_validity(c, materials, &kernel);
}

} // namespace vksonar
