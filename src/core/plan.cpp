// make_plan: turns a validated SonarConfig and a scene into sizes, tables and resolved effects. Its steps on
// the depth pass's pixel grid are in plan_grid.cpp, those on the beams in plan_beams.cpp (plan_steps.h).
#include "core/plan.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

#include <unistd.h>

#include "core/angles.h"
#include "core/plan_focus.h"
#include "core/plan_steps.h"
#include "core/sonar_math.hpp"
#include "core/subpixel.h"
#include "scene/scene_data.h"

namespace vksonar {

using namespace plan_steps;

namespace {

// Absorption below this over the two-way range window is invisible on any display: README "Effects: only what the scene
// calls for".
constexpr double kAbsorptionAutoThresholdDb = 0.1;
// Neighbours whose slant range differs by more than 5% are treated as another surface by the
// Sobel stage (docs/pipeline.md §2); the one-sided fallback handles them.
constexpr float kEdgeRelativeJump = 0.05f;
// The side-lobe kernel's reach in beams: enough for a kernel over the whole fan of 2048 beams (the
// plan stops it at the last beam anyway); weights are beams x (2 K + 1) floats.
constexpr std::uint32_t kMaxSidelobeHalfTaps = 2047;

void resolve(bool& on, EffectMode mode, bool auto_value, const char* name, const std::string& auto_why,
             std::vector<EffectState>& states) {
    if (mode == EffectMode::automatic) {
        on = auto_value;
        states.push_back({name, on, "auto: " + auto_why});
    } else {
        on = mode == EffectMode::on;
        states.push_back({name, on, on ? "on in config" : "off in config"});
    }
}

std::string gigabytes(double bytes) {
    return fmt(bytes / 1e9) + " GB";
}

// Refuses, before anything is allocated, a depth pass whose buffers no machine here can hold: the
// range-profile buffer (bins x columns floats) past the 4 GiB that any Vulkan device can bind as one
// storage buffer (maxStorageBufferRange is a 32-bit count), or all per-ping buffers together past
// half this machine's physical memory (the CPU backend and lavapipe keep them in host memory).
Result<void> check_memory(const Plan& p) {
    const double pixels = double(p.columns) * p.rows;
    const double padded_bins = double((p.bins + 3u) & ~3u);
    const double profiles = padded_bins * p.profile_columns * 4.0;
    // Per pixel: depth, material id, normals + cos, echo (energy, range), face normals, and with
    // line_array the cone coordinate: 52 bytes. Per polar cell: beam profiles, polar, clean, intensity,
    // display and the staging copy: 24 bytes.
    const double total = pixels * 52.0 + profiles + padded_bins * p.beams * 24.0;
    const std::string grid = std::to_string(p.columns) + " x " + std::to_string(p.rows) + " pixels, " +
                             std::to_string(p.bins) + " bins x " + std::to_string(p.beams) + " beams";
    if (profiles > 4294967295.0)
        return make_error(ErrorCode::invalid_argument,
                          "config: the range-profile buffer would hold " + gigabytes(profiles) + " (" +
                              std::to_string(p.bins) + " bins x " + std::to_string(p.profile_columns) +
                              " profile columns), past the 4 GiB a Vulkan device can bind; lower bins (or bandwidth) "
                              "or accuracy.pixels_per_beam");
    const long pages = ::sysconf(_SC_PHYS_PAGES), page_size = ::sysconf(_SC_PAGE_SIZE);
    if (pages > 0 && page_size > 0) {
        const double memory = double(pages) * double(page_size);
        if (total > 0.5 * memory)
            return make_error(ErrorCode::invalid_argument,
                              "config: the depth pass and its buffers would need " + gigabytes(total) + " (" + grid +
                                  "), more than half of this machine's " + gigabytes(memory) +
                                  "; lower accuracy.pixels_per_beam, accuracy.rows_per_vfov or bins");
    }
    return {};
}

} // namespace

Result<std::vector<double>> beam_table(const SonarConfig& c) {
    std::vector<double> angles;
    const double half = 0.5 * c.hfov_deg * kDegToRad;
    if (!c.beam_angles_deg.empty()) {
        angles.reserve(c.beam_angles_deg.size());
        for (double a : c.beam_angles_deg)
            angles.push_back(a * kDegToRad);
        for (std::size_t j = 1; j < angles.size(); ++j) {
            if (!(angles[j] < angles[j - 1])) {
                return make_error(ErrorCode::invalid_argument,
                                  "config: beam_angles must be strictly decreasing (port first); entry " +
                                      std::to_string(j) + " = " + fmt(c.beam_angles_deg[j]));
            }
        }
        return angles;
    }
    angles.resize(c.beams);
    for (std::uint32_t j = 0; j < c.beams; ++j) {
        const double t = 1.0 - (2.0 * j + 1.0) / c.beams; // +1 - 1/N .. -1 + 1/N: centres of N sectors
        if (c.beam_spacing == BeamSpacing::equisine && c.hfov_deg <= 180.0) {
            angles[j] = std::asin(t * std::sin(half));
        } else {
            angles[j] = t * half;
        }
    }
    return angles;
}

std::uint32_t ResolvedEffects::shader_flags() const {
    std::uint32_t f = 0;
    if (incidence) f |= shared::kEffectIncidence;
    if (vertical_pattern) f |= shared::kEffectVerticalPattern;
    if (horizontal_pattern) f |= shared::kEffectHorizontalPattern;
    if (spreading) f |= shared::kEffectSpreading;
    if (absorption) f |= shared::kEffectAbsorption;
    return f;
}

double francois_garrison_db_per_m(double frequency_hz, double temperature_c, double salinity_ppt, double depth_m,
                                  double ph, double sound_speed_mps) {
    // Francois & Garrison, JASA 72(6) 1982: boric acid, magnesium sulphate and pure-water terms.
    const double f = frequency_hz / 1000.0; // kHz
    const double T = temperature_c, S = salinity_ppt, D = depth_m, c = sound_speed_mps;
    const double theta = 273.0 + T;
    // Boric acid
    const double A1 = 8.86 / c * std::pow(10.0, 0.78 * ph - 5.0);
    const double P1 = 1.0;
    const double f1 = 2.8 * std::sqrt(S / 35.0) * std::pow(10.0, 4.0 - 1245.0 / theta);
    // Magnesium sulphate
    const double A2 = 21.44 * S / c * (1.0 + 0.025 * T);
    const double P2 = 1.0 - 1.37e-4 * D + 6.2e-9 * D * D;
    const double f2 = 8.17 * std::pow(10.0, 8.0 - 1990.0 / theta) / (1.0 + 0.0018 * (S - 35.0));
    // Pure water
    const double A3 = T <= 20.0 ? 4.937e-4 - 2.59e-5 * T + 9.11e-7 * T * T - 1.50e-8 * T * T * T
                                : 3.964e-4 - 1.146e-5 * T + 1.45e-7 * T * T - 6.5e-10 * T * T * T;
    const double P3 = 1.0 - 3.83e-5 * D + 4.9e-10 * D * D;
    const double f_sq = f * f;
    const double db_per_km =
        A1 * P1 * f1 * f_sq / (f1 * f1 + f_sq) + A2 * P2 * f2 * f_sq / (f2 * f2 + f_sq) + A3 * P3 * f_sq;
    return db_per_km / 1000.0;
}

double chebyshev_a(double sidelobe_db) {
    return std::acosh(std::pow(10.0, -sidelobe_db / 20.0));
}

double pattern_constant(BeamPattern shape, double beamwidth_rad, double chebyshev_a_value) {
    const double half = 0.5 * beamwidth_rad;
    switch (shape) {
    case BeamPattern::box:
        return 0.0;
    case BeamPattern::gaussian:
        return std::log(2.0) / (half * half);
    case BeamPattern::sinc:
    case BeamPattern::hann:
    case BeamPattern::chebyshev: {
        // Find x in (0, 3) where the power pattern (same formula as the shaders, via k = 1 and the
        // angle asin(x) scaled out) falls to 0.5, then k = x / sin(half). On (0, 3) the power is above
        // 0.5 only from the axis to that point: sinc and hann reach their first nulls past x = 3, and
        // chebyshev's side lobes (past x = sqrt(A^2 + (pi/2)^2), which may be < 3) stay at their
        // level, below -10 dB; so the bisection finds the main lobe's half-power point.
        const std::uint32_t id = static_cast<std::uint32_t>(shape);
        auto power_at_x = [id, chebyshev_a_value](double x) {
            // pattern_power evaluates k * sin(a); with a = pi/2 and k = x this is exactly x.
            return math_f64::pattern_power(id, x, 0.0, chebyshev_a_value, 3.14159265358979323846 / 2.0);
        };
        double lo = 0.0, hi = 3.0;
        for (int i = 0; i < 100; ++i) {
            const double mid = 0.5 * (lo + hi);
            (power_at_x(mid) > 0.5 ? lo : hi) = mid;
        }
        return 0.5 * (lo + hi) / std::sin(half);
    }
    }
    return 0.0;
}

HorizontalLobes horizontal_lobes(std::uint32_t shape, double k, double half_width_rad, double chebyshev_a_value,
                                 double reach_rad) {
    // Walk out from the axis in steps of 1/200 of the reach: the first local minimum is the first
    // null, the largest value beyond it the strongest side lobe (none for monotone patterns). Not past
    // 90 deg: nothing reaches a beam from behind its baffled aperture (plan_beams.cpp
    // pattern_at_separation), where the pattern in sin(a) would mirror its main lobe.
    reach_rad = std::min(reach_rad, 0.5 * kPi);
    HorizontalLobes lobes;
    constexpr int kSteps = 2000;
    double previous = math_f64::pattern_power(shape, k, half_width_rad, chebyshev_a_value, 0.0);
    bool falling = true;
    double peak = 0.0;
    for (int i = 1; i <= kSteps; ++i) {
        const double a = reach_rad * i / kSteps;
        const double value = math_f64::pattern_power(shape, k, half_width_rad, chebyshev_a_value, a);
        if (falling && value > previous) {
            falling = false;
            lobes.first_null_rad = reach_rad * (i - 1) / kSteps;
        }
        if (!falling) peak = std::max(peak, value);
        previous = value;
    }
    lobes.peak_sidelobe_db = peak > 0.0 ? 10.0 * std::log10(peak) : -std::numeric_limits<double>::infinity();
    return lobes;
}

// Largest scattering factor f over all incidences (docs/pipeline.md §3): 1 for lambert and constant;
// for rough, 1 + specular_ratio * the peak of specular_facet(c, a) = exp(-a (1/c^2 - 1)) / c^5,
// which is 1 at c = 1 when a = 1 / (2 m^2) >= 2.5, else exp(a - 2.5) / (0.4 a)^2.5 at c^2 = 0.4 a.
double scatter_factor_peak(const shared::MaterialGpu& m) {
    if (m.model != shared::kScatterRough) return 1.0;
    const double a = m.inv_two_slope_sq;
    const double facet = a >= 2.5 ? 1.0 : std::exp(a - 2.5) / std::pow(0.4 * a, 2.5);
    return 1.0 + m.specular_ratio * facet;
}

// make_plan, as named steps (each reads the config from p.config and what the steps before it set; the
// grid's and the beams' are in plan_steps.h).
namespace {

// Step, first: the beam geometry the config asks for, where it can hold.
void plan_beam_geometry(Plan& p) {
    p.line_array = resolves_to_line_array(p.config, &p.beam_geometry_why);
}

// Step: the range window: bin width, the echo stage's gate, bin centres.
void plan_range_window(Plan& p) {
    const SonarConfig& c = p.config;
    p.bin_width_m = (c.range_max_m - c.range_min_m) / p.bins;
    // The range gate: a footprint reaches at most kMaxFootprintBins / 2 bins from its pixel, a tent one
    // bin, the nearest bin none. Below range_min the gate stops at half of it (the near plane must stay
    // in front of the sonar; footprints are narrow that close).
    const double kernel_half_bins = c.range_kernel == RangeKernel::footprint ? 0.5 * shared::kMaxFootprintBins
                                    : c.range_kernel == RangeKernel::tent    ? 1.0
                                                                             : 0.0;
    p.gate_margin_m = kernel_half_bins * p.bin_width_m;
    p.gate_min_m = std::max(c.range_min_m - p.gate_margin_m, 0.5 * c.range_min_m);
    p.gate_max_m = c.range_max_m + p.gate_margin_m;

    p.bin_range_m.resize(p.bins);
    for (std::uint32_t k = 0; k < p.bins; ++k)
        p.bin_range_m[k] = c.range_min_m + (k + 0.5) * p.bin_width_m;
}

// Step (after the pixel grid and the gate): the depth pass's clip planes.
void plan_clip_planes(Plan& p) {
    // Clip planes: the corner ray of a slice reaches gate_min at view z = gate_min / |(u, v, 1)|, so the
    // near plane sits there (slightly closer), the far plane at gate_max, and the echo stage cuts at the
    // exact slant range.
    double corner = 0.0;
    for (const ViewGeometry& v : p.view_geometry)
        corner = std::max(corner, std::sqrt(1.0 + v.tan_half_h * v.tan_half_h + v.tan_half_v * v.tan_half_v));
    p.near_m = 0.999 * p.gate_min_m / corner;
    p.far_m = p.gate_max_m;
    p.depth_a = p.near_m * p.far_m / (p.far_m - p.near_m);
    p.depth_b = -p.near_m / (p.far_m - p.near_m);
}

// Step: the horizontal pattern's constants.
void plan_horizontal_pattern(Plan& p) {
    const SonarConfig& c = p.config;
    const double hbw = c.horizontal_beamwidth_deg * kDegToRad;
    p.hpattern_chebyshev_a =
        c.horizontal_pattern == BeamPattern::chebyshev ? chebyshev_a(c.horizontal_sidelobe_db) : 0.0;
    p.hpattern_k = pattern_constant(c.horizontal_pattern, hbw, p.hpattern_chebyshev_a);
    p.hpattern_halfwidth_rad = 0.5 * hbw;
    p.element_k = p.line_array && c.mode == SonarMode::physical ? kPi * c.element_width : 0.0;
}

// Step: the acoustic materials as uploaded. any_angle_dependent: a drawn material depends on incidence.
Result<void> plan_materials(Plan& p, const SceneData& scene, bool& any_angle_dependent) {
    const SonarConfig& c = p.config;
    // Materials: one per scene material, or the config default if the scene has none.
    any_angle_dependent = false;
    if (scene.materials.empty()) {
        p.materials.push_back(
            {static_cast<float>(std::pow(10.0, c.default_backscatter_db / 10.0)), shared::kScatterLambert, 0.0f, 0.0f});
        any_angle_dependent = !scene.draws.empty();
    }
    // Only materials that something is drawn with count for the incidence rule: a scene always carries
    // the implicit Lambert "default" material, used or not.
    // The depth pass's id image holds the material in its low 16 bits (the instance in the high ones
    // when labels are asked for; kNoMaterial's low half, 0xffff, means no hit).
    if (scene.materials.size() >= shared::kMaterialIdMask)
        return make_error(ErrorCode::invalid_argument, "scene: " + std::to_string(scene.materials.size()) +
                                                           " materials; at most " +
                                                           std::to_string(shared::kMaterialIdMask - 1));
    std::vector<bool> drawn(scene.materials.size(), false);
    for (const SceneDraw& d : scene.draws)
        if (d.material < drawn.size()) drawn[d.material] = true;
    for (std::size_t i = 0; i < scene.materials.size(); ++i) {
        const AcousticMaterial& m = scene.materials[i];
        // Engines fill materials by hand (Scene::add_material); the glTF loader has checked its own.
        if (const auto valid = m.validate(); !valid)
            return make_error(ErrorCode::invalid_argument,
                              "material " + std::to_string(i) + " '" + m.name + "': " + valid.error().message);
        const double db = std::isfinite(m.backscatter_db) ? m.backscatter_db : c.default_backscatter_db;
        const double backscatter_linear = std::pow(10.0, db / 10.0);
        shared::MaterialGpu gpu{static_cast<float>(backscatter_linear), shader_id(m.model), 0.0f, 0.0f};
        if (m.model == AcousticMaterial::Model::rough) {
            p.rough_materials = true;
            const double slope_sq = m.rms_slope * m.rms_slope;
            const double facet_peak = std::pow(10.0, m.reflection_db / 10.0) / (8.0 * kPi * slope_sq);
            gpu.specular_ratio = static_cast<float>(facet_peak / backscatter_linear);
            gpu.inv_two_slope_sq = static_cast<float>(0.5 / slope_sq);
        }
        any_angle_dependent |= drawn[i] && gpu.model != shared::kScatterConstant;
        p.materials.push_back(gpu);
    }

    return {};
}

// Step: the effects on demand, and the side-lobe kernel's half width in beams (0: none).
std::uint32_t plan_effects(Plan& p, const SceneData& scene, bool any_angle_dependent, double& reach,
                           bool& main_lobe_only) {
    const SonarConfig& c = p.config;
    const double hbw = c.horizontal_beamwidth_deg * kDegToRad;
    // Effects (README "Effects: only what the scene calls for").
    const double alpha = c.absorption_db_per_m >= 0.0
                             ? c.absorption_db_per_m
                             : francois_garrison_db_per_m(c.frequency_hz, c.temperature_c, c.salinity_ppt,
                                                          c.water_depth_m, c.ph, c.sound_speed_mps);
    const double absorption_window_db = 2.0 * alpha * c.range_max_m;

    // Side-lobe kernel reach in beams (from the finest spacing, so a non-uniform table is covered): in
    // angle (planar), or in sine with line_array, where the beams near the fan's edges are closer in
    // sine and their pattern reaches over more of them (the beam widens as 1 / cos(theta)).
    double min_spacing = std::numeric_limits<double>::infinity();
    for (std::uint32_t j = 1; j < p.beams; ++j) {
        const double a = p.beam_angle_rad[j - 1], b = p.beam_angle_rad[j];
        min_spacing = std::min(min_spacing, p.line_array ? std::sin(a) - std::sin(b) : a - b);
    }
    reach = c.sidelobe_kernel_beamwidths * hbw;
    // Side lobes that stay below the display floor even for a target at the top of the display window
    // (strongest side lobe, dB re the main lobe, below -(db_max - db_min)) show nothing: with the
    // effect on auto the kernel then stops at the first null (main lobe only).
    std::string lobes_why;
    if (c.effects.horizontal_pattern == EffectMode::automatic) {
        const HorizontalLobes lobes = horizontal_lobes(shader_id(c.horizontal_pattern), p.hpattern_k,
                                                       p.hpattern_halfwidth_rad, p.hpattern_chebyshev_a, reach);
        const double window_db = c.db_max - c.db_min;
        if (lobes.first_null_rad > 0.0 && lobes.peak_sidelobe_db < -window_db) {
            main_lobe_only = true;
            reach = std::min(reach, lobes.first_null_rad);
            lobes_why = "; side lobes (" + fmt(lobes.peak_sidelobe_db) + " dB) stay below the " + fmt(window_db) +
                        " dB display window: main lobe only";
        }
    }
    std::uint32_t half_taps = 0;
    p.circular = c.hfov_deg >= 360.0 && p.beams > 1;
    if (p.beams > 1) {
        const double k = std::floor(sidelobe_reach(p, reach) / min_spacing);
        // On a circle a kernel wider than the fan would count a source beam twice.
        const double widest = p.circular ? std::floor((p.beams - 1) / 2.0) : p.beams - 1.0;
        half_taps = static_cast<std::uint32_t>(std::min<double>({k, widest, double(kMaxSidelobeHalfTaps)}));
    }

    ResolvedEffects& e = p.effects;
    resolve(e.incidence, c.effects.incidence, any_angle_dependent, "incidence",
            any_angle_dependent ? "a drawn material uses the angle-dependent Lambert model"
                                : "no drawn material is angle-dependent: no normals pass",
            e.states);
    // Where the pixel grid stops, the vertical side lobes beyond it are not simulated: say how far it goes.
    const bool tiers = p.views > p.slices;
    const std::string elevations =
        p.elevation_gate_sin <= 1.0 && !tiers
            ? " at elevations within +-" + fmt(std::round(std::asin(p.elevation_gate_sin) / kDegToRad * 10.0) / 10.0) +
                  " deg (the depth pass's coverage; side lobes beyond it are not simulated)"
        : tiers ? " at every elevation (beyond the main band through vertical_sidelobes)"
                : "";
    resolve(e.vertical_pattern, c.effects.vertical_pattern, true, "vertical_pattern",
            "vertical beam pattern always shapes seabed returns" + elevations, e.states);
    e.vertical_sidelobes = tiers;
    e.states.push_back({"vertical_sidelobes", tiers, p.vertical_sidelobes_why});
    resolve(e.horizontal_pattern, c.effects.horizontal_pattern, half_taps > 0, "horizontal_pattern",
            half_taps > 0 ? "side-lobe kernel spans " + std::to_string(2 * half_taps + 1) + " beams" + lobes_why
                          : "beam pattern narrower than the beam spacing",
            e.states);
    resolve(e.spreading, c.effects.spreading, true, "spreading", "two-way spherical spreading, 40 log r", e.states);
    resolve(e.absorption, c.effects.absorption, absorption_window_db >= kAbsorptionAutoThresholdDb, "absorption",
            "2 alpha range_max = " + fmt(absorption_window_db) + " dB (alpha = " + fmt(alpha * 1000.0) +
                " dB/km) vs threshold " + fmt(kAbsorptionAutoThresholdDb) + " dB",
            e.states);
    resolve(e.speckle, c.effects.speckle, true, "speckle", "fully developed speckle", e.states);
    resolve(e.ambient_noise, c.effects.ambient_noise, true, "ambient_noise", "noise floor NL - DI", e.states);
    resolve(e.tvg, c.effects.tvg, false, "tvg", "raw received levels; turn on for display gain", e.states);
    // What the echo stage applies and TVG compensates: nothing when the effect is off (plan.h).
    p.alpha_db_per_m = e.absorption ? alpha : 0.0;
    // beam_sampling with the kernel as resolved here (the main-lobe-only rule above may shorten it below the
    // beam spacing).
    p.validity = model_validity(c, scene.materials, e.horizontal_pattern && half_taps > 0, sidelobe_reach(p, reach));

    return e.horizontal_pattern ? half_taps : 0;
}

// Step, last: the compute stages' uniform block, from the finished plan.
void plan_gpu_params(Plan& p) {
    const SonarConfig& c = p.config;
    const ResolvedEffects& e = p.effects;
    shared::SonarParams& g = p.params;
    g.columns = p.columns;
    g.rows = p.rows;
    g.slice_columns = p.slice_columns;
    g.tier_columns = p.tier_columns;
    g.tier_cone_reach = p.tier_cone_reach;
    g.slices = p.slices;
    g.beams = p.beams;
    g.bins = p.bins;
    g.effect_flags = e.shader_flags();
    g.near_column_taps = p.near_column_taps;
    g.far_cells = p.far_cells;
    g.far_channels = p.far_channels;
    g.tan_half_h = static_cast<float>(p.tan_half_h);
    g.tan_half_v = static_cast<float>(p.tan_half_v);
    g.depth_a = static_cast<float>(p.depth_a);
    g.depth_b = static_cast<float>(p.depth_b);
    g.range_min_m = static_cast<float>(c.range_min_m);
    g.range_max_m = static_cast<float>(c.range_max_m);
    g.gate_min_m = static_cast<float>(p.gate_min_m);
    g.gate_max_m = static_cast<float>(p.gate_max_m);
    g.bin_width_m = static_cast<float>(p.bin_width_m);
    g.inv_bin_width_m = static_cast<float>(1.0 / p.bin_width_m);
    g.alpha_db_per_m = static_cast<float>(p.alpha_db_per_m);
    g.absorption_per_bin = static_cast<float>(
        std::min(2.0 * p.alpha_db_per_m * 0.2302585092994046 * p.bin_width_m, double(shared::kMaxAbsorptionPerBin)));
    g.vpattern_k = static_cast<float>(p.vpattern_k);
    g.element_k = static_cast<float>(p.element_k);
    g.vpattern_shape = shader_id(c.vertical_pattern);
    g.range_kernel = shader_id(c.range_kernel);
    g.normal_method = shader_id(c.normal_method);
    // The face-normal attachment costs a colour target and a copy per frame: only when it is used.
    p.face_normals = e.incidence && c.normal_method == NormalMethod::geometric;
    g.edge_relative_jump = kEdgeRelativeJump;
    g.circular = p.circular ? 1u : 0u;
    // fp16 echo storage: scale energies by a power of 2 (exact both ways) so that the brightest
    // possible pixel (brightest material, facing, on axis, the largest pixel solid angle, at the
    // near edge of the gate, or the far edge without spreading) lands near 2^15 < 65504. Echoes
    // more than ~2^40 (120 dB) below it underflow to 0.
    g.echo_half = c.intermediates == IntermediatePrecision::fp16 ? 1u : 0u;
    {
        double brightest = 0.0;
        for (const auto& m : p.materials)
            brightest = std::max(brightest, m.backscatter_linear * scatter_factor_peak(m));
        const double omega = (2.0 * p.tan_half_h / p.slice_columns) * (2.0 * p.tan_half_v / p.rows);
        const double r = e.spreading ? p.gate_min_m : p.gate_max_m; // the gate's edges: echo computes there
        const double peak = brightest * omega * (e.spreading ? 1.0 / (r * r) : r * r);
        const int exponent = peak > 0.0 ? static_cast<int>(std::floor(std::log2(32768.0 / peak))) : 0;
        g.echo_scale = std::ldexp(1.0f, std::clamp(exponent, -120, 120));
    }
    g.vpattern_halfwidth_rad = static_cast<float>(p.vpattern_halfwidth_rad);
    g.vpattern_chebyshev_a = static_cast<float>(p.vpattern_chebyshev_a);
    g.elevation_gate_sin = static_cast<float>(p.elevation_gate_sin);
    g.profile_columns = p.profile_columns;
    g.line_array = p.line_array ? 1u : 0u;
    // the same floats plan_profile_columns computed the CPU's cone coordinates from
    g.cone_half_fov_rad = p.line_array ? static_cast<float>(0.5 * c.hfov_deg * kDegToRad) : 0.0f;
    g.inv_cone_step = p.line_array ? static_cast<float>(1.0 / p.cone_step_rad) : 0.0f;
}

} // namespace

Result<Plan> make_plan(const SonarConfig& config, const SceneData& scene, const HostPixelGrid* host_grid) {
    if (auto valid = config.validate(); !valid) {
        return make_error(ErrorCode::invalid_argument, "config: " + valid.error().message);
    }
    Plan p;
    p.config = config;

    auto beams_or = beam_table(config);
    if (!beams_or) return beams_or.error();
    p.beam_angle_rad = std::move(beams_or.value());
    p.beams = static_cast<std::uint32_t>(p.beam_angle_rad.size());
    p.bins = config.range_bins();

    plan_beam_geometry(p);
    if (host_grid != nullptr) {
        use_host_grid(p, *host_grid);
    } else if (auto grid = plan_pixel_grid(p); !grid) {
        return grid.error();
    } else if (auto tiers = plan_tier_views(p); !tiers) {
        return tiers.error();
    }
    plan_profile_columns(p);
    if (auto fits = check_memory(p); !fits) return fits.error();
    plan_cone_table(p);
    plan_range_window(p);
    plan_clip_planes(p);
    plan_horizontal_pattern(p);
    bool any_angle_dependent = false;
    if (auto materials = plan_materials(p, scene, any_angle_dependent); !materials) return materials.error();
    double reach = 0.0;
    bool main_lobe_only = false;
    const std::uint32_t half_taps = plan_effects(p, scene, any_angle_dependent, reach, main_lobe_only);
    if (auto bands = plan_focus_bands(p, p.effects.horizontal_pattern && half_taps > 0); !bands) return bands.error();
    // A host camera may see beyond the sonar's fan: those columns feed no beam (make_plan's own grid
    // folds its few edge columns into the edge beams).
    plan_column_tables(p, host_grid != nullptr ? 0.5 * config.hfov_deg * kDegToRad
                                               : std::numeric_limits<double>::infinity());
    // Far side lobes only for a pattern that has side lobes: a gaussian or box pattern falls away
    // monotonically, and the far grid's coarse cells would smear its steep skirt out over beamwidths (a
    // gaussian read -65 dB at 3-6 beamwidths, where it is below -100 dB).
    const bool has_sidelobes =
        config.horizontal_pattern != BeamPattern::gaussian && config.horizontal_pattern != BeamPattern::box;
    if (auto kernel = plan_sidelobe_kernel(p, half_taps, reach, !main_lobe_only && has_sidelobes); !kernel)
        return kernel.error();
    resolve_noise_floor(p);
    plan_grain(p);
    plan_gpu_params(p);
    plan_subpixel(p, scene);
    if (p.subpixel_capacity > 0) {
        p.subpixel_silent_material =
            static_cast<std::uint32_t>(p.materials.size()); // < kMaterialIdMask (plan_materials)
        p.materials.push_back(shared::MaterialGpu{0.0f, shared::kScatterConstant, 0.0f, 0.0f});
    }
    return p;
}

} // namespace vksonar
