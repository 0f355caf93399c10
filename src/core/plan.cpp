// make_plan: turns a validated SonarConfig and a scene into sizes, tables and resolved effects.
#include "core/plan.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

#include <unistd.h>

#include "core/angles.h"
#include "core/sonar_math.hpp"
#include "core/subpixel.h"
#include "scene/scene_data.h"

namespace vksonar {
namespace {

// The public enums and the shaders' constants (sonar_shared.h) are the same numbers, checked here:
// adding a model or a shape to one without the other fails to compile.
constexpr std::uint32_t shader_id(BeamPattern shape) {
    return static_cast<std::uint32_t>(shape);
}
static_assert(shader_id(BeamPattern::box) == shared::kPatternBox &&
              shader_id(BeamPattern::sinc) == shared::kPatternSinc &&
              shader_id(BeamPattern::hann) == shared::kPatternHann &&
              shader_id(BeamPattern::gaussian) == shared::kPatternGaussian &&
              shader_id(BeamPattern::chebyshev) == shared::kPatternChebyshev);
constexpr std::uint32_t shader_id(AcousticMaterial::Model model) {
    return static_cast<std::uint32_t>(model);
}
static_assert(shader_id(AcousticMaterial::Model::lambert) == shared::kScatterLambert &&
              shader_id(AcousticMaterial::Model::constant) == shared::kScatterConstant &&
              shader_id(AcousticMaterial::Model::rough) == shared::kScatterRough);
constexpr std::uint32_t shader_id(RangeKernel kernel) {
    return static_cast<std::uint32_t>(kernel);
}
static_assert(shader_id(RangeKernel::nearest) == shared::kRangeKernelNearest &&
              shader_id(RangeKernel::tent) == shared::kRangeKernelTent &&
              shader_id(RangeKernel::footprint) == shared::kRangeKernelFootprint);
constexpr std::uint32_t shader_id(NormalMethod method) {
    return static_cast<std::uint32_t>(method);
}
static_assert(shader_id(NormalMethod::sobel3) == shared::kNormalsSobel3 &&
              shader_id(NormalMethod::sobel5) == shared::kNormalsSobel5 &&
              shader_id(NormalMethod::geometric) == shared::kNormalsGeometric);

// Absorption below this over the two-way range window is invisible on any display: README "Effects: only what the scene
// calls for".
constexpr double kAbsorptionAutoThresholdDb = 0.1;
// Neighbours whose slant range differs by more than 5% are treated as another surface by the
// Sobel stage (docs/pipeline.md §2); the one-sided fallback handles them.
constexpr float kEdgeRelativeJump = 0.05f;
// lavapipe and most GPUs allow 16384-wide framebuffers; more pixel columns than that buys nothing.
constexpr std::uint32_t kMaxColumns = 16384;
constexpr std::uint32_t kMaxRows = 4096;
// The side-lobe kernel's reach in beams: enough for a kernel over the whole fan of 2048 beams (the
// plan stops it at the last beam anyway); weights are beams x (2 K + 1) floats.
constexpr std::uint32_t kMaxSidelobeHalfTaps = 2047;

std::string fmt(double v) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%g", v);
    return buf;
}

// Beam centre table, port first (strictly decreasing azimuth).
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
    // null, the largest value beyond it the strongest side lobe (none for monotone patterns).
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

void assign_columns_to_beams(Plan& p, double exclude_beyond_rad) {
    const std::vector<double>& b = p.beam_angle_rad;
    const std::uint32_t columns = static_cast<std::uint32_t>(p.column_azimuth_rad.size()); // profile columns
    p.column_beam.resize(columns);
    p.column_weight.resize(columns);
    for (std::uint32_t col = 0; col < columns; ++col) {
        const double a = p.column_azimuth_rad[col];
        if (std::abs(a) > exclude_beyond_rad) {
            p.column_beam[col] = p.beams; // no beam: the resample tables skip it
            p.column_weight[col] = 0.0f;
        } else if (p.circular && (a > b.front() || a < b.back())) {
            // The seam between beam 0 and beam beams-1 (at b.back() + 2 pi): a tent across it, so a
            // target at 180 deg is beamformed like one anywhere else.
            const double two_pi = 2.0 * 3.14159265358979323846;
            const double beyond_beam0 = a > b.front() ? a - b.front() : a + two_pi - b.front();
            p.column_beam[col] = p.beams - 1;
            p.column_weight[col] = static_cast<float>(beyond_beam0 / (b.back() + two_pi - b.front()));
        } else if (a >= b.front()) {
            p.column_beam[col] = 0;
            p.column_weight[col] = 1.0f;
        } else if (a <= b.back()) {
            p.column_beam[col] = p.beams - 1;
            p.column_weight[col] = 1.0f;
        } else {
            // first beam j+1 with b[j+1] < a (b decreasing), so b[j] >= a > b[j+1]
            const auto it = std::upper_bound(b.begin(), b.end(), a, [](double x, double y) { return x > y; });
            const std::uint32_t j = static_cast<std::uint32_t>(it - b.begin()) - 1;
            p.column_beam[col] = j;
            p.column_weight[col] = static_cast<float>((a - b[j + 1]) / (b[j] - b[j + 1]));
        }
    }
    p.beam_column_begin.assign(p.beams, columns);
    p.beam_column_end.assign(p.beams, 0);
    for (std::uint32_t col = 0; col < columns; ++col) {
        for (std::uint32_t j : {p.column_beam[col], p.column_beam[col] + 1}) {
            if (j >= p.beams) continue;
            p.beam_column_begin[j] = std::min(p.beam_column_begin[j], col);
            p.beam_column_end[j] = std::max(p.beam_column_end[j], col + 1);
        }
    }
    if (p.circular) { // the edge beams gather seam columns at both ends of the pixel grid
        for (std::uint32_t j : {0u, p.beams - 1}) {
            p.beam_column_begin[j] = 0;
            p.beam_column_end[j] = columns;
        }
    }
    for (std::uint32_t j = 0; j < p.beams; ++j) {
        if (p.beam_column_begin[j] > p.beam_column_end[j]) p.beam_column_begin[j] = p.beam_column_end[j] = 0;
    }
}

// make_plan, as named steps (each reads the config from p.config and what the steps before it set).
namespace {

// Step, first: the beam geometry the config asks for, where it can hold.
void plan_beam_geometry(Plan& p) {
    const SonarConfig& c = p.config;
    p.line_array = false;
    if (c.beam_geometry == BeamGeometry::planar) {
        p.beam_geometry_why = "planar in config";
    } else if (c.mode != SonarMode::physical) {
        p.beam_geometry_why = "planar: the legacy modes reproduce their plugins' planar beams";
    } else if (c.hfov_deg >= 180.0) {
        p.beam_geometry_why = "planar: a fan of " + fmt(c.hfov_deg) +
                              " deg has no single array axis (hfov < 180 for "
                              "line_array)";
    } else {
        p.line_array = true;
        p.beam_geometry_why = "line_array in config";
    }
}

// The pixel columns that resolve an angle `width_rad` at pixels_per_beam per resolved angle (the finer
// of the beam spacing and the beamwidth).
double columns_for(const Plan& p, double width_rad) {
    const SonarConfig& c = p.config;
    const double hfov = c.hfov_deg * kDegToRad;
    const double spacing = p.beams > 1 ? hfov / p.beams : hfov;
    const double resolved_angle = std::min(spacing, c.horizontal_beamwidth_deg * kDegToRad);
    return std::ceil(c.pixels_per_beam * width_rad / resolved_angle);
}

// Step: vksonar's own pixel grid and the vertical pattern's constants (its coverage reaches the
// pattern's first null).
Result<void> plan_pixel_grid(Plan& p) {
    const SonarConfig& c = p.config;
    const double hfov = c.hfov_deg * kDegToRad;

    // Vertical coverage (physical mode): at least vertical_coverage beamwidths and, with the vertical
    // pattern on, its main lobe out to the first null, where the pattern's power reaches 0 (cut at
    // 20 deg, the sinc pattern of a 20-degree beam is still at -17 dB: the first seabed returns, which
    // come from there, lost 5-20 dB). And at every azimuth of a slice: a perspective slice sees its edge
    // columns' rays at lower elevations (tan(elevation) = v / sqrt(1 + u^2)), so v reaches further by
    // sqrt(1 + tan_half_h^2) to hold the elevation there (a 60-degree slice's edges saw only +-17.5 of
    // +-20 degrees). The null is found by sampling (horizontal_lobes: steps of 0.045 deg); gaussian and
    // box patterns have none. Rows keep rows_per_vfov per beamwidth of the centre column's coverage
    // (docs/pipeline.md). The legacy modes keep their plugins' plain vertical field of view.
    const double vfov = c.vfov_deg * kDegToRad;
    p.vpattern_chebyshev_a = c.vertical_pattern == BeamPattern::chebyshev ? chebyshev_a(c.vertical_sidelobe_db) : 0.0;
    p.vpattern_k = pattern_constant(c.vertical_pattern, vfov, p.vpattern_chebyshev_a);
    p.vpattern_halfwidth_rad = 0.5 * vfov;
    double half_coverage = 0.5 * std::min(c.vfov_deg * c.vertical_coverage, 170.0) * kDegToRad;
    if (c.mode == SonarMode::physical) {
        if (c.effects.vertical_pattern != EffectMode::off) {
            const HorizontalLobes lobes = horizontal_lobes(shader_id(c.vertical_pattern), p.vpattern_k,
                                                           p.vpattern_halfwidth_rad, p.vpattern_chebyshev_a, 0.5 * kPi);
            half_coverage = std::max(half_coverage, lobes.first_null_rad);
        }
        half_coverage = std::min(half_coverage, 85.0 * kDegToRad);
    }

    // The azimuths the pixel grid covers: the fan (planar), or with line_array the fan's edge cones as
    // far as the covered elevations take them: the cone sin(theta) = cos(elevation) sin(azimuth) of the
    // edge beam reaches azimuth asin(sin(hfov / 2) / cos(half_coverage)). Up to 89 degrees: each slice
    // must stay short of 90 (the cone coordinate then increases along a row), and what lies beyond is
    // a sliver at the largest elevations of a fan close to 180 degrees.
    double covered = hfov;
    if (p.line_array) {
        const double reach = std::sin(0.5 * hfov) / std::cos(half_coverage);
        covered = 2.0 * std::min(reach < 1.0 ? std::asin(reach) : 0.5 * kPi, 89.0 * kDegToRad);
        covered = std::max(covered, hfov);
    }

    // Pixel grid: enough columns that pixels_per_beam of them fall in the finer of the beam spacing and
    // the beamwidth, split into slices no wider than max_slice_deg.
    const double covered_deg = p.line_array ? covered / kDegToRad : c.hfov_deg;
    const double wanted_columns = columns_for(p, covered);
    p.slices = static_cast<std::uint32_t>(std::ceil(covered_deg / c.max_slice_deg - 1e-9));
    p.slices = std::max(1u, p.slices);
    if (p.slices > shared::kMaxSlices) {
        const std::string span = p.line_array ? "the " + fmt(covered_deg) +
                                                    "-degree span a line array's pixel grid covers (hfov " +
                                                    fmt(c.hfov_deg) + ")"
                                              : "hfov " + fmt(c.hfov_deg);
        return make_error(ErrorCode::invalid_argument, "config: accuracy.max_slice = " + fmt(c.max_slice_deg) +
                                                           " needs " + std::to_string(p.slices) + " slices for " +
                                                           span + "; at most " + std::to_string(shared::kMaxSlices));
    }
    if (wanted_columns > kMaxColumns) {
        return make_error(ErrorCode::invalid_argument,
                          "config: " + fmt(wanted_columns) +
                              " pixel columns needed (accuracy.pixels_per_beam = " + fmt(c.pixels_per_beam) +
                              ", beams = " + std::to_string(p.beams) + ") exceeds " + std::to_string(kMaxColumns));
    }
    const std::uint32_t min_columns = 8; // a 1-beam sonar still needs a few columns for its pattern
    const std::uint32_t total = std::max(min_columns, static_cast<std::uint32_t>(wanted_columns));
    p.slice_columns = (total + p.slices - 1) / p.slices;
    p.columns = p.slice_columns * p.slices;
    p.slice_width_rad = covered / p.slices;
    p.tan_half_h = std::tan(0.5 * p.slice_width_rad);

    double tan_half_v = std::tan(half_coverage);
    if (c.mode == SonarMode::physical) {
        tan_half_v *= std::sqrt(1.0 + p.tan_half_h * p.tan_half_h);
        p.elevation_gate_sin = std::sin(half_coverage);
    }
    p.tan_half_v = tan_half_v;
    p.vertical_coverage_rad = 2.0 * std::atan(p.tan_half_v); // at the slice's centre column
    const double rows = std::ceil(c.rows_per_vfov * p.vertical_coverage_rad / (c.vfov_deg * kDegToRad));
    if (rows > kMaxRows) {
        return make_error(ErrorCode::invalid_argument,
                          "config: accuracy.rows_per_vfov = " + std::to_string(c.rows_per_vfov) + " gives " +
                              fmt(rows) + " rows; at most " + std::to_string(kMaxRows));
    }
    p.rows = std::max(2u, static_cast<std::uint32_t>(rows));

    // The slices: level cameras at their centre azimuths. The float table rounds the double centre's
    // cosine and sine; the double geometry takes them of the float centre (as the depth pass always has).
    p.view_geometry.assign(p.slices, ViewGeometry{});
    p.slice_info.assign(p.slices, shared::SliceInfo{});
    for (std::uint32_t s = 0; s < p.slices; ++s) {
        const double centre = 0.5 * covered - (s + 0.5) * p.slice_width_rad;
        const float centre_f = static_cast<float>(centre), cs = static_cast<float>(std::cos(centre)),
                    sn = static_cast<float>(std::sin(centre));
        const double cd = std::cos(double(centre_f)), sd = std::sin(double(centre_f));
        ViewGeometry& view = p.view_geometry[s];
        view = {
            {cd, sd, 0.0},        {sd, -cd, 0.0}, {0.0, 0.0, -1.0}, p.tan_half_h, p.tan_half_v, -p.elevation_gate_sin,
            p.elevation_gate_sin, false,          {1.0, 0.0},       {1.0, 0.0}};
        shared::SliceInfo& info = p.slice_info[s];
        info.center_azimuth_rad = centre_f;
        info.tan_half_h = static_cast<float>(p.tan_half_h);
        info.tan_half_v = static_cast<float>(p.tan_half_v);
        info.forward_x = cs;
        info.forward_y = sn;
        info.right_x = sn;
        info.right_y = -cs;
        info.down_z = -1.0f;
        info.sin_elevation_min = -static_cast<float>(p.elevation_gate_sin);
        info.sin_elevation_max = static_cast<float>(p.elevation_gate_sin);
    }
    p.views = p.slices;

    return {};
}

// A tier view's pixel size relative to a slice's: the square root of the ratio of their solid angles
// (the views share the grid's rows: their half extents' products, the horizontal ones per column), for
// a tier view `columns` wide.
double tier_pixel_ratio(const Plan& p, double tan_h, double tan_v, std::uint32_t columns) {
    return std::sqrt((tan_h / columns) / (p.tan_half_h / p.slice_columns) * (tan_v / p.tan_half_v));
}

// The most the tier views' pixels may be coarser than the slices' before the side lobes are left out.
constexpr double kMaxTierPixelRatio = 4.0;

// Whether the line array's cone coordinate increases along every row of the view (its axis cosine, the
// ray's y over its length, decreases with u), sampled at every pixel centre in double, with a margin.
bool cone_increases_along_rows(const Plan& p, const ViewGeometry& v, std::uint32_t columns) {
    for (std::uint32_t row = 0; row < p.rows; ++row) {
        const double vv = math_f64::pixel_coord(row, p.rows, v.tan_half_v);
        double previous = 2.0;
        for (std::uint32_t col = 0; col < columns; ++col) {
            const double u = math_f64::pixel_coord(col, columns, v.tan_half_h);
            const double y = v.forward[1] + u * v.right[1] + vv * v.down[1];
            const double axis = y / std::sqrt(1.0 + u * u + vv * vv);
            if (!(axis < previous - 1e-6)) return false;
            previous = axis;
        }
    }
    return true;
}

// A tier view's camera: looking at azimuth `centre`, pitched by `pitch` (positive: down), right axis level.
ViewGeometry tier_camera(double centre, double pitch) {
    ViewGeometry v;
    const double c = std::cos(centre), s = std::sin(centre), cb = std::cos(pitch), sb = std::sin(pitch);
    const double f[3] = {cb * c, cb * s, -sb}, r[3] = {s, -c, 0.0};
    for (int i = 0; i < 3; ++i) {
        v.forward[i] = f[i];
        v.right[i] = r[i];
    }
    v.down[0] = f[1] * r[2] - f[2] * r[1]; // down = forward x right, as a slice's (0, 0, -1)
    v.down[1] = f[2] * r[0] - f[0] * r[2];
    v.down[2] = f[0] * r[1] - f[1] * r[0];
    return v;
}

// The half extents a camera needs to hold the cell azimuth [a0, a1] x elevation [e0, e1] (sampled
// densely on its edges, where a cell's projection has its extremes, and on a coarse interior grid);
// false if a direction of the cell is not in front of it.
bool cell_extents(const ViewGeometry& v, double a0, double a1, double e0, double e1, double& tan_h, double& tan_v) {
    constexpr int kEdge = 96, kInner = 12;
    tan_h = tan_v = 0.0;
    auto hold = [&](double a, double e) {
        const double d[3] = {std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e)};
        const double z = d[0] * v.forward[0] + d[1] * v.forward[1] + d[2] * v.forward[2];
        if (!(z > 0.05)) return false;
        tan_h = std::max(tan_h, std::abs(d[0] * v.right[0] + d[1] * v.right[1] + d[2] * v.right[2]) / z);
        tan_v = std::max(tan_v, std::abs(d[0] * v.down[0] + d[1] * v.down[1] + d[2] * v.down[2]) / z);
        return true;
    };
    for (int i = 0; i <= kEdge; ++i) {
        const double t = double(i) / kEdge, a = a0 + t * (a1 - a0), e = e0 + t * (e1 - e0);
        if (!hold(a, e0) || !hold(a, e1) || !hold(a0, e) || !hold(a1, e)) return false;
    }
    for (int i = 1; i < kInner; ++i)
        for (int j = 1; j < kInner; ++j)
            if (!hold(a0 + (a1 - a0) * i / kInner, e0 + (e1 - e0) * j / kInner)) return false;
    return true;
}

// The tier views of one band (elevations [e0, e1], down: below the slices): the azimuths in front of
// the array, [-90, 90) degrees (its baffled elements hear nothing from behind), in n equal wedges, n
// the fewest whose cameras' pixels stay within accuracy.tier_pixel_ratio of the slices' in angle (the
// square root of their solid angles' ratio; at most 8 wedges, the finest they allow if none does). The
// side lobes are 13 dB and more below the main lobe: their returns need the range footprint more than
// fine azimuths (a flat seabed's closed form holds within 0.07 dB at 2.85x, tests/hard_cases). Each
// camera is pitched to need the smallest pixels; its half extents are its cell's, judged at a slice's
// width (plan_tier_views then narrows the views and widens each by two pixels past its cell).
std::vector<ViewGeometry> tier_band(const Plan& p, double e0, double e1, bool down) {
    std::vector<ViewGeometry> best;
    double best_ratio = std::numeric_limits<double>::infinity();
    for (int n = 1; n <= 8; ++n) {
        std::vector<ViewGeometry> band;
        double worst = 0.0;
        for (int w = 0; w < n; ++w) {
            const double a0 = -0.5 * kPi + kPi * w / n, a1 = a0 + kPi / n, centre = 0.5 * (a0 + a1);
            ViewGeometry chosen;
            double chosen_ratio = std::numeric_limits<double>::infinity();
            for (int i = 1; i <= 90; ++i) {
                const double pitch = i * kDegToRad;
                ViewGeometry v = tier_camera(centre, down ? pitch : -pitch);
                double tan_h = 0.0, tan_v = 0.0;
                if (!cell_extents(v, a0, a1, e0, e1, tan_h, tan_v)) continue;
                const double ratio = tier_pixel_ratio(p, tan_h, tan_v, p.slice_columns);
                if (ratio < chosen_ratio) {
                    chosen_ratio = ratio;
                    v.tan_half_h = tan_h;
                    v.tan_half_v = tan_v;
                    v.wedge = true;
                    v.wedge_start[0] = std::cos(a0);
                    v.wedge_start[1] = std::sin(a0);
                    v.wedge_end[0] = std::cos(a1);
                    v.wedge_end[1] = std::sin(a1);
                    chosen = v;
                }
            }
            worst = std::max(worst, chosen_ratio);
            band.push_back(chosen);
        }
        if (worst < best_ratio) {
            best_ratio = worst;
            best = band;
        }
        if (worst <= p.config.tier_pixel_ratio) break;
    }
    return best;
}

// Step (after the pixel grid): the vertical side lobes. Where they are simulated, tier views below
// and above the slices' band see every elevation beyond the elevation gate; they join the pixel
// grid after the slices. Only with a line array's beams (a tier pixel's beam is its cone, which any
// direction has; planar beams are the pixel columns' azimuths) and a vertical pattern with side lobes.
Result<void> plan_tier_views(Plan& p) {
    const SonarConfig& c = p.config;
    const EffectMode mode = c.effects.vertical_sidelobes;
    const bool has_lobes = c.vertical_pattern == BeamPattern::sinc || c.vertical_pattern == BeamPattern::hann ||
                           c.vertical_pattern == BeamPattern::chebyshev;
    std::string without;
    if (c.mode != SonarMode::physical)
        without = "the legacy modes have no vertical side lobes";
    else if (c.effects.vertical_pattern == EffectMode::off)
        without = "the vertical pattern is off";
    else if (!has_lobes)
        without = "the " + std::string(c.vertical_pattern == BeamPattern::box ? "box" : "gaussian") +
                  " vertical pattern has no side lobes";
    else if (!p.line_array)
        without = "planar beams (" + p.beam_geometry_why + "): tier views need the line_array beam geometry";
    else if (!(p.elevation_gate_sin < 1.0))
        without = "the depth pass covers every elevation";
    if (mode == EffectMode::off) {
        p.vertical_sidelobes_why = "off in config";
        return {};
    }
    if (!without.empty()) {
        if (mode == EffectMode::on)
            return make_error(ErrorCode::invalid_argument, "config: effects.vertical_sidelobes = on, but " + without);
        p.vertical_sidelobes_why = "auto: " + without;
        return {};
    }
    const double gate = std::asin(p.elevation_gate_sin);
    std::vector<ViewGeometry> tiers = tier_band(p, -0.5 * kPi, -gate, true);
    const std::size_t below = tiers.size();
    for (const ViewGeometry& v : tier_band(p, gate, 0.5 * kPi, false))
        tiers.push_back(v);
    // The tier views' width: the fewest columns (at most a slice's) that keep their pixels within
    // accuracy.tier_pixel_ratio of the slices'; the side lobes' share of the frame's time follows it.
    // Each camera is then widened by two pixels past its cell.
    const auto widened = [&](ViewGeometry v, std::uint32_t columns) {
        v.tan_half_h *= 1.0 + 4.0 / columns;
        v.tan_half_v *= 1.0 + 4.0 / p.rows;
        return v;
    };
    const auto worst_ratio_at = [&](std::uint32_t columns) {
        double worst = 0.0;
        for (const ViewGeometry& cell : tiers) {
            const ViewGeometry v = widened(cell, columns);
            worst = std::max(worst, tier_pixel_ratio(p, v.tan_half_h, v.tan_half_v, columns));
        }
        return worst;
    };
    constexpr std::uint32_t kMinTierColumns = 8;
    const std::uint32_t full = p.slice_columns;
    std::uint32_t tier_columns = full;
    if (const double at_full = worst_ratio_at(full); at_full < c.tier_pixel_ratio) {
        const double scale = at_full / c.tier_pixel_ratio; // the ratio grows as 1 / sqrt(columns)
        tier_columns = std::clamp(static_cast<std::uint32_t>(std::ceil(full * scale * scale)), kMinTierColumns, full);
        while (tier_columns < full && worst_ratio_at(tier_columns) > c.tier_pixel_ratio)
            ++tier_columns;
    }
    for (ViewGeometry& v : tiers)
        v = widened(v, tier_columns);
    // What the tier views can hold: pixels at most kMaxTierPixelRatio times the slices' (a fan of a few
    // degrees has slices of a few columns; its tier views would be as many columns over 90 degrees), and
    // a cone coordinate that increases along each of their rows (the profile stage's gather needs it).
    double worst_ratio = 0.0;
    bool monotonic = true;
    for (const ViewGeometry& v : tiers) {
        worst_ratio = std::max(worst_ratio, tier_pixel_ratio(p, v.tan_half_h, v.tan_half_v, tier_columns));
        monotonic = monotonic && cone_increases_along_rows(p, v, tier_columns);
    }
    if (worst_ratio > kMaxTierPixelRatio || !monotonic) {
        const std::string why = !monotonic
                                    ? "the tier views' rows would not run along the beams (vfov " + fmt(c.vfov_deg) +
                                          ", hfov " + fmt(c.hfov_deg) + ")"
                                    : "the tier views' pixels would be " + fmt(std::round(worst_ratio * 10) / 10) +
                                          "x the slices' (at most " + fmt(kMaxTierPixelRatio) + "x)";
        if (mode == EffectMode::on)
            return make_error(ErrorCode::invalid_argument, "config: effects.vertical_sidelobes = on, but " + why);
        p.vertical_sidelobes_why = "auto: off: " + why;
        return {};
    }
    if (p.slices + tiers.size() > shared::kMaxViews)
        return make_error(ErrorCode::invalid_argument,
                          "config: accuracy.max_slice = " + fmt(c.max_slice_deg) + " gives " +
                              std::to_string(p.slices) + " slices and " + std::to_string(tiers.size()) +
                              " tier views for the vertical side lobes; at most " + std::to_string(shared::kMaxViews) +
                              " views (raise max_slice or set effects.vertical_sidelobes off)");
    // Each band's elevation range, as its views gate it: beyond the slices' gate (the slices keep
    // |sin e| <= gate, the tiers the rest, so every direction is counted once).
    const float gate_f = static_cast<float>(p.elevation_gate_sin);
    for (std::size_t i = 0; i < tiers.size(); ++i) {
        ViewGeometry& v = tiers[i];
        const bool down = i < below;
        v.sin_elevation_min = down ? -2.0 : std::nextafter(p.elevation_gate_sin, 2.0);
        v.sin_elevation_max = down ? std::nextafter(-p.elevation_gate_sin, -2.0) : 2.0;
        shared::SliceInfo info{};
        info.center_azimuth_rad = static_cast<float>(std::atan2(v.forward[1], v.forward[0]));
        info.tan_half_h = static_cast<float>(v.tan_half_h);
        info.tan_half_v = static_cast<float>(v.tan_half_v);
        info.forward_x = static_cast<float>(v.forward[0]);
        info.forward_y = static_cast<float>(v.forward[1]);
        info.forward_z = static_cast<float>(v.forward[2]);
        info.right_x = static_cast<float>(v.right[0]);
        info.right_y = static_cast<float>(v.right[1]);
        info.right_z = static_cast<float>(v.right[2]);
        info.down_x = static_cast<float>(v.down[0]);
        info.down_y = static_cast<float>(v.down[1]);
        info.down_z = static_cast<float>(v.down[2]);
        info.sin_elevation_min = down ? -2.0f : std::nextafter(gate_f, 2.0f);
        info.sin_elevation_max = down ? std::nextafter(-gate_f, -2.0f) : 2.0f;
        info.wedge = 1u;
        info.wedge_start_x = static_cast<float>(v.wedge_start[0]);
        info.wedge_start_y = static_cast<float>(v.wedge_start[1]);
        info.wedge_end_x = static_cast<float>(v.wedge_end[0]);
        info.wedge_end_y = static_cast<float>(v.wedge_end[1]);
        p.view_geometry.push_back(v);
        p.slice_info.push_back(info);
    }
    p.views = static_cast<std::uint32_t>(p.view_geometry.size());
    p.tier_columns = tier_columns;
    p.columns = p.slice_columns * p.slices + tier_columns * (p.views - p.slices);
    p.vertical_sidelobes_why =
        (mode == EffectMode::on ? std::string("on in config") : std::string("auto")) +
        ": the vertical pattern's side lobes beyond +-" + fmt(std::round(gate / kDegToRad * 10.0) / 10.0) +
        " deg, to the nadir and the zenith: " + std::to_string(below) + " + " + std::to_string(tiers.size() - below) +
        " tier views, pixels up to " + fmt(std::round(worst_ratio * 100.0) / 100.0) + "x the slices'";
    return {};
}

// Step, instead of plan_pixel_grid: a host engine's pixel grid (one slice) and the vertical
// pattern's constants.
void use_host_grid(Plan& p, const HostPixelGrid& grid) {
    const SonarConfig& c = p.config;
    const double vfov = c.vfov_deg * kDegToRad;
    p.vpattern_chebyshev_a = c.vertical_pattern == BeamPattern::chebyshev ? chebyshev_a(c.vertical_sidelobe_db) : 0.0;
    p.vpattern_k = pattern_constant(c.vertical_pattern, vfov, p.vpattern_chebyshev_a);
    p.vpattern_halfwidth_rad = 0.5 * vfov;
    p.slices = 1;
    p.slice_columns = grid.columns;
    p.columns = grid.columns;
    p.rows = grid.rows;
    p.tan_half_h = grid.tan_half_h;
    p.tan_half_v = grid.tan_half_v;
    p.slice_width_rad = 2.0 * std::atan(grid.tan_half_h);
    p.vertical_coverage_rad = 2.0 * std::atan(grid.tan_half_v);
    p.views = 1;
    ViewGeometry view;
    view.tan_half_h = grid.tan_half_h;
    view.tan_half_v = grid.tan_half_v;
    p.view_geometry.assign(1, view);
    shared::SliceInfo info{};
    info.tan_half_h = static_cast<float>(grid.tan_half_h);
    info.tan_half_v = static_cast<float>(grid.tan_half_v);
    info.forward_x = 1.0f;
    info.right_y = -1.0f;
    info.down_z = -1.0f;
    info.sin_elevation_min = -2.0f;
    info.sin_elevation_max = 2.0f;
    p.slice_info.assign(1, info);
    p.vertical_sidelobes_why = "a host engine's depth image: its own pixel grid";
}

// Step (after the pixel grid): the columns of the range profiles. line_array: the cone columns over the
// fan, as many as the planar grid would have pixel columns there.
void plan_profile_columns(Plan& p) {
    if (!p.line_array) {
        p.profile_columns = p.columns;
        p.cone_step_rad = 0.0;
        p.pixel_cone_coord.clear();
        return;
    }
    const double hfov = p.config.hfov_deg * kDegToRad;
    p.profile_columns = std::max(8u, static_cast<std::uint32_t>(columns_for(p, hfov)));
    p.cone_step_rad = hfov / p.profile_columns;
}

// Step (after the memory check): line_array, every pixel's cone coordinate. Along each view's row it
// must not decrease (the profile stage's gather searches a view's row for a cone column's pixels).
void plan_cone_table(Plan& p) {
    if (!p.line_array) return;
    const double hfov = p.config.hfov_deg * kDegToRad;
    const float half_fov = static_cast<float>(0.5 * hfov);
    const float inv_step = static_cast<float>(1.0 / p.cone_step_rad);
    p.pixel_cone_coord.resize(static_cast<std::size_t>(p.rows) * p.columns);
    for (std::uint32_t row = 0; row < p.rows; ++row) {
        for (std::uint32_t col = 0; col < p.columns; ++col) {
            const std::uint32_t index = view_of_column(p, col), first = view_first_column(p, index);
            const math_f32::PixelView view = math_f32::view_of_slice(p.slice_info[index]);
            const float v = math_f32::pixel_coord(row, p.rows, view.tan_half_v);
            const float u = math_f32::pixel_coord(col - first, view_columns(p, index), view.tan_half_h);
            const float axis = math_f32::array_axis_cosine(u, v, view);
            p.pixel_cone_coord[std::size_t(row) * p.columns + col] = math_f32::cone_coord(axis, half_fov, inv_step);
            // A tier view's (plan_tier_views checked its rows in double, with a margin): held non-decreasing
            // against float rounding, the same table for both backends. The slices' as before.
            float& x = p.pixel_cone_coord[std::size_t(row) * p.columns + col];
            if (col != first && index >= p.slices) x = std::max(x, (&x)[-1]);
        }
    }
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

// The side-lobe kernel's reach `reach` (an angle from the beam's axis) in the unit the beams are
// separated in: the angle (planar), or its sine (line_array: the pattern is a function of
// sin(theta') - sin(theta)).
double sidelobe_reach(const Plan& p, double reach) {
    if (!p.line_array) return reach;
    // Two beams' sines differ by up to 2 (a fan's two edges): past a quarter turn the reach goes on
    // growing, continuously, to 2 at half a turn.
    return reach <= 0.5 * kPi ? std::sin(reach) : 1.0 + std::sin(std::min(reach - 0.5 * kPi, 0.5 * kPi));
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
    p.validity = model_validity(c, scene.materials);

    return e.horizontal_pattern ? half_taps : 0;
}

// Step: which beams each pixel column feeds (tent on the beam table). Columns at |azimuth| beyond
// exclude_beyond_rad feed none.
void plan_column_tables(Plan& p, double exclude_beyond_rad) {
    p.column_azimuth_rad.resize(p.profile_columns);
    if (p.line_array) { // the cone columns' steering angles
        const double half_fov = 0.5 * p.config.hfov_deg * kDegToRad;
        for (std::uint32_t col = 0; col < p.profile_columns; ++col)
            p.column_azimuth_rad[col] = half_fov - (col + 0.5) * p.cone_step_rad;
        assign_columns_to_beams(p, exclude_beyond_rad);
        return;
    }
    for (std::uint32_t col = 0; col < p.columns; ++col) {
        const std::uint32_t s = col / p.slice_columns;
        const double u = math_f64::pixel_coord(col % p.slice_columns, p.slice_columns, p.tan_half_h);
        p.column_azimuth_rad[col] = math_f64::pixel_azimuth(p.slice_info[s].center_azimuth_rad, u);
    }
    assign_columns_to_beams(p, exclude_beyond_rad);
}

// The horizontal power pattern at separation `sep` of two beams in the side-lobe kernel's unit: the
// angle, or with line_array its sine. A line array's aperture patterns are functions of
// sin(theta') - sin(theta) over its whole range [-2, 2]; the others (box, gaussian) are read at the
// angle whose sine it is (at most 90 degrees).
double pattern_at_separation(const Plan& p, double sep) {
    const std::uint32_t hshape = shader_id(p.config.horizontal_pattern);
    if (p.circular) sep = std::remainder(sep, 2.0 * kPi); // into [-pi, pi]
    if (p.line_array && hshape != shared::kPatternBox && hshape != shared::kPatternGaussian)
        return math_f64::aperture_pattern_power(hshape, p.hpattern_k, p.hpattern_chebyshev_a, sep);
    const double angle = p.line_array ? std::asin(std::clamp(sep, -1.0, 1.0)) : sep;
    return math_f64::pattern_power(hshape, p.hpattern_k, p.hpattern_halfwidth_rad, p.hpattern_chebyshev_a, angle);
}

// The share of the pattern at |sep| that the far grid carries: 0 up to half the reach, 1 from the
// reach on, a smoothstep between (smooth, so the coarse grid sees no edge).
double far_ramp(double abs_sep, double reach_units) {
    const double x = std::clamp((abs_sep - 0.5 * reach_units) / (0.5 * reach_units), 0.0, 1.0);
    return x * x * (3.0 - 2.0 * x);
}

// The separation variable of beam j: its angle, or with line_array its sine.
double beam_position(const Plan& p, std::uint32_t j) {
    return p.line_array ? std::sin(p.beam_angle_rad[j]) : p.beam_angle_rad[j];
}

// Step: the far side lobes' grid (Plan::far_cells), when the kernel stops short of the fan. The cells
// are as narrow as far_sidelobe_cell * reach, and at most kMaxFarCells.
void plan_far_sidelobes(Plan& p, double reach_units) {
    p.far_cells = 0;
    p.far_channels = 1;
    p.far_beam_cell.clear();
    p.far_cell_beams.clear();
    p.far_weight.clear();
    const double cell_fraction = p.config.far_sidelobe_cell;
    if (!(cell_fraction > 0.0) || p.beams < 2 || !(reach_units > 0.0)) return;
    const double span = p.circular ? 2.0 * kPi : beam_position(p, 0) - beam_position(p, p.beams - 1);
    if (0.5 * reach_units >= span) return; // every pair of beams is within the kernel's exact part
    const double wanted = cell_fraction * reach_units;
    std::uint32_t cells = 0;
    double step = 0.0;
    if (p.circular) {
        cells = static_cast<std::uint32_t>(std::clamp(std::ceil(span / wanted), 3.0, double(shared::kMaxFarCells)));
        step = span / cells;
    } else {
        cells =
            static_cast<std::uint32_t>(std::clamp(std::ceil(span / wanted) + 1.0, 2.0, double(shared::kMaxFarCells)));
        step = span / (cells - 1);
    }
    p.far_cells = cells;
    // A line array's sinc^2 pattern is sin^2(k du) / (k du)^2, and sin^2(k (u_s - u_j)) =
    // (1 - cos 2k u_s cos 2k u_j - sin 2k u_s sin 2k u_j) / 2: the crests and nulls factor into a phase of
    // each beam, and only the smooth 1 / (k du)^2 goes on the grid (three channels: the energy, and the
    // energy times each beam's cos 2k u and sin 2k u). Other patterns keep the lobes' mean (one channel).
    const bool phased = p.line_array && shader_id(p.config.horizontal_pattern) == shared::kPatternSinc;
    p.far_channels = phased ? 3u : 1u;
    // Each beam's two cells and the share of the second: position x = (first beam's position - its own) / step.
    p.far_beam_cell.assign(std::size_t(p.beams) * 8, 0.0f);
    std::vector<std::uint32_t> first(cells, p.beams), last(cells, 0);
    for (std::uint32_t j = 0; j < p.beams; ++j) {
        double x = (beam_position(p, 0) - beam_position(p, j)) / step;
        if (p.circular) x = std::fmod(std::fmod(x, double(cells)) + cells, double(cells));
        auto c0 = static_cast<std::uint32_t>(std::floor(x));
        if (p.circular)
            c0 %= cells;
        else
            c0 = std::min(c0, cells - 2);
        const std::uint32_t c1 = p.circular ? (c0 + 1) % cells : c0 + 1;
        const float share = static_cast<float>(std::clamp(x - c0, 0.0, 1.0)); // c0 = floor(x) but at the last cell
        p.far_beam_cell[8 * j + 0] = static_cast<float>(c0);
        p.far_beam_cell[8 * j + 1] = static_cast<float>(c1);
        p.far_beam_cell[8 * j + 2] = share;
        if (phased) {
            const double phase = 2.0 * p.hpattern_k * beam_position(p, j);
            p.far_beam_cell[8 * j + 4] = static_cast<float>(std::cos(phase));
            p.far_beam_cell[8 * j + 5] = static_cast<float>(std::sin(phase));
        }
        for (std::uint32_t c : {c0, c1}) {
            first[c] = std::min(first[c], j);
            last[c] = std::max(last[c], j);
        }
    }
    p.far_cell_beams.assign(std::size_t(cells) * 2, 0);
    for (std::uint32_t c = 0; c < cells; ++c) {
        if (first[c] > last[c]) continue; // no beam feeds it
        p.far_cell_beams[2 * c] = first[c];
        p.far_cell_beams[2 * c + 1] = last[c] + 1;
    }
    // far_weight: cell b into cell a depends on a - b only; the pattern (phased: its smooth part
    // 1 / (2 (k du)^2)) times the ramp, averaged over one cell by the midpoint rule.
    constexpr int kSamples = 64;
    p.far_weight.assign(2 * std::size_t(cells) - 1, 0.0f);
    for (std::int64_t d = -std::int64_t(cells) + 1; d < std::int64_t(cells); ++d) {
        double sum = 0.0;
        for (int i = 0; i < kSamples; ++i) {
            const double sep = (double(d) + (i + 0.5) / kSamples - 0.5) * step;
            const double folded = p.circular ? std::remainder(sep, 2.0 * kPi) : sep;
            const double ramp = far_ramp(std::abs(folded), reach_units);
            if (ramp == 0.0) continue; // also keeps 1 / du^2 away from du = 0
            const double x = p.hpattern_k * sep;
            sum += (phased ? 0.5 / (x * x) : pattern_at_separation(p, sep)) * ramp;
        }
        p.far_weight[std::size_t(d + cells - 1)] = static_cast<float>(sum / kSamples);
    }
}

// Step: the side-lobe kernel along beams (its taps out to the reach; the far side lobes beyond).
void plan_sidelobe_kernel(Plan& p, std::uint32_t half_taps, double reach, bool far_sidelobes) {
    // Side-lobe kernel: weight of beam j - K + t into beam j = b_h^2 at their separation.
    p.sidelobe_taps = 2 * half_taps + 1;
    const double reach_units = sidelobe_reach(p, reach);
    // A kernel asked to reach across the fan (bench accuracy's reference) is exact everywhere it reaches.
    const bool stops_short = reach < p.config.hfov_deg * kDegToRad;
    if (half_taps > 0 && far_sidelobes && stops_short) plan_far_sidelobes(p, reach_units);
    if (p.far_cells > 0) // meta.json and Frame::effects say how the pattern reaches past the kernel
        for (EffectState& state : p.effects.states)
            if (state.name == "horizontal_pattern")
                state.why += "; far side lobes over the fan on " + std::to_string(p.far_cells) + " cells" +
                             (p.far_channels == 3 ? " (sinc^2 crests and nulls exact)" : " (the lobes' mean level)");
    p.sidelobe_weight.assign(static_cast<std::size_t>(p.beams) * p.sidelobe_taps, 0.0f);
    for (std::uint32_t j = 0; j < p.beams; ++j) {
        for (std::uint32_t t = 0; t < p.sidelobe_taps; ++t) {
            std::int64_t src = static_cast<std::int64_t>(j) - half_taps + t;
            if (p.circular) src = (src + p.beams) % p.beams; // half_taps < beams / 2: one wrap at most
            if (src < 0 || src >= p.beams) continue;
            double sep = beam_position(p, static_cast<std::uint32_t>(src)) - beam_position(p, j);
            float w = 1.0f;
            if (half_taps > 0) {
                const double folded = p.circular ? std::abs(std::remainder(sep, 2.0 * kPi)) : std::abs(sep);
                const double near_share = p.far_cells > 0 ? 1.0 - far_ramp(folded, reach_units) : 1.0;
                w = folded <= reach_units + 1e-12 ? static_cast<float>(pattern_at_separation(p, sep) * near_share)
                                                  : 0.0f;
            }
            p.sidelobe_weight[j * p.sidelobe_taps + t] = w;
        }
    }
    p.sidelobe_tap_begin.assign(p.beams, 0);
    p.sidelobe_tap_end.assign(p.beams, 0);
    for (std::uint32_t j = 0; j < p.beams; ++j) {
        const float* w = p.sidelobe_weight.data() + std::size_t(j) * p.sidelobe_taps;
        std::uint32_t begin = 0, end = p.sidelobe_taps;
        while (begin < end && w[begin] == 0.0f)
            ++begin;
        while (end > begin && w[end - 1] == 0.0f)
            --end;
        p.sidelobe_tap_begin[j] = begin;
        p.sidelobe_tap_end[j] = end;
    }
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
    g.slices = p.slices;
    g.beams = p.beams;
    g.bins = p.bins;
    g.effect_flags = e.shader_flags();
    g.sidelobe_taps = p.sidelobe_taps;
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
    g.vpattern_k = static_cast<float>(p.vpattern_k);
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
    // A host camera may see beyond the sonar's fan: those columns feed no beam (make_plan's own grid
    // folds its few edge columns into the edge beams).
    plan_column_tables(p, host_grid != nullptr ? 0.5 * config.hfov_deg * kDegToRad
                                               : std::numeric_limits<double>::infinity());
    plan_sidelobe_kernel(p, half_taps, reach, !main_lobe_only);
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
