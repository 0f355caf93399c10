// The noise terms of the sonar equation (README "The model"): the ambient noise level NL in the receive
// band, from the sea's noise spectrum where the config says "auto", and the receive directivity index DI,
// from the beam patterns where it says "auto". The host noise stage adds 10^((NL - DI_j) / 10) Exp(1) to
// each cell of beam j: DI_j is the broadside beam's, less what a line array loses by steering.
#include <algorithm>
#include <cmath>

#include "core/angles.h"
#include "core/plan.h"
#include "core/plan_steps.h"
#include "core/sonar_math.hpp"

namespace vksonar {

using namespace plan_steps;

namespace {

// Midpoint sum of f over [a, b] in n steps.
template <class F> double integrate(F f, double a, double b, int n) {
    const double h = (b - a) / n;
    double sum = 0.0;
    for (int i = 0; i < n; ++i)
        sum += f(a + (i + 0.5) * h);
    return sum * h;
}

// Steps for a pattern of -3 dB width `width_rad` over a span of pi: 64 per beamwidth (a sinc's lobes are
// about 1.1 beamwidths apart), at least 4096.
int steps_for(double width_rad) {
    return static_cast<int>(std::clamp(std::ceil(64.0 * kPi / width_rad), 4096.0, double(1 << 21)));
}

} // namespace

bool resolves_to_line_array(const SonarConfig& c, std::string* why) {
    const auto say = [why](std::string text) {
        if (why != nullptr) *why = std::move(text);
    };
    if (c.beam_geometry == BeamGeometry::planar) {
        say("planar in config");
        return false;
    }
    if (c.mode != SonarMode::physical) {
        say("planar: the legacy modes reproduce their plugins' planar beams");
        return false;
    }
    if (c.hfov_deg >= 180.0) {
        say("planar: a fan of " + fmt(c.hfov_deg) + " deg has no single array axis (hfov < 180 for line_array)");
        return false;
    }
    say("line_array in config");
    return true;
}

double ambient_noise_spectrum_db(double frequency_hz, double wind_speed_mps, double shipping_activity) {
    // Coates' fits to the Wenz curves (as in Stojanovic, "On the relationship between capacity and distance
    // in an underwater acoustic communication channel", 2007), f in kHz, dB re 1 uPa^2/Hz: turbulence,
    // shipping, wind (bubbles and spray) and the molecules' thermal noise, which sets the floor of every
    // imaging sonar's band (above about 100 kHz).
    const double f = frequency_hz / 1000.0;
    const double lg = std::log10(f);
    const double turbulence = 17.0 - 30.0 * lg;
    const double shipping = 40.0 + 20.0 * (shipping_activity - 0.5) + 26.0 * lg - 60.0 * std::log10(f + 0.03);
    const double wind = 50.0 + 7.5 * std::sqrt(wind_speed_mps) + 20.0 * lg - 40.0 * std::log10(f + 0.4);
    const double thermal = -15.0 + 20.0 * lg;
    double power = 0.0;
    for (const double db : {turbulence, shipping, wind, thermal})
        power += std::pow(10.0, db / 10.0);
    return 10.0 * std::log10(power);
}

double receive_band_hz(const SonarConfig& c) {
    if (c.bandwidth_hz > 0.0) return c.bandwidth_hz; // validate(): at most 2 f
    // A receiver matched to bins of width dr passes the band c / 2 dr (the range resolution's); bins finer
    // than a quarter wavelength ask for more than the band 0 .. 2 f any pulse at f has: at most that.
    const double bin_width = (c.range_max_m - c.range_min_m) / std::max<std::uint32_t>(c.range_bins(), 1);
    return std::min(c.sound_speed_mps / (2.0 * bin_width), 2.0 * c.frequency_hz);
}

double band_noise_level_db(double frequency_hz, double band_hz, double wind_speed_mps, double shipping_activity) {
    // The spectrum summed over f +- B/2 (thermal noise grows as f^2: over a band as wide as 2 f the sum is
    // 1.25 dB above B times the level at f). A band reaching down to 0 Hz starts at f / 10 instead: the
    // turbulence and shipping terms grow without bound towards 0 Hz, and a receiver's front end filters
    // there (the thermal part of such a band loses 0.04 %).
    const double low = std::max(frequency_hz - 0.5 * band_hz, 0.1 * frequency_hz);
    const double high = frequency_hz + 0.5 * band_hz;
    const double power = integrate(
        [&](double f) {
            return std::pow(10.0, ambient_noise_spectrum_db(f, wind_speed_mps, shipping_activity) / 10.0);
        },
        low, high, 256);
    return 10.0 * std::log10(power);
}

double beam_directivity_index_db(const SonarConfig& c, bool line_array) {
    // DI = 10 log10(4 pi / Omega), Omega the receive power pattern's solid angle over the front half-space
    // (a baffled array hears nothing from behind). The pattern is b_h^2 b_v^2; for narrow horizontal beams
    // Omega separates: planar beams (functions of azimuth phi), dOmega = cos(psi) dpsi dphi:
    //   Omega = int b_h^2(phi) dphi * int b_v^2(psi) cos(psi) dpsi;
    // line-array beams (functions of u = cos(psi) sin(phi)), dphi = du / cos(psi) near broadside:
    //   Omega = int b_h^2(u) du * int b_v^2(psi) dpsi.
    // (tests/noise_floor_test.cpp checks this against the whole double integral.)
    const double hbw = c.horizontal_beamwidth_deg * kDegToRad, vbw = c.vfov_deg * kDegToRad;
    const double h_cheb = c.horizontal_pattern == BeamPattern::chebyshev ? chebyshev_a(c.horizontal_sidelobe_db) : 0.0;
    const double v_cheb = c.vertical_pattern == BeamPattern::chebyshev ? chebyshev_a(c.vertical_sidelobe_db) : 0.0;
    const double h_k = pattern_constant(c.horizontal_pattern, hbw, h_cheb);
    const double v_k = pattern_constant(c.vertical_pattern, vbw, v_cheb);
    const std::uint32_t h_shape = shader_id(c.horizontal_pattern), v_shape = shader_id(c.vertical_pattern);
    const auto horizontal = [&](double a) { return math_f64::pattern_power(h_shape, h_k, 0.5 * hbw, h_cheb, a); };
    const auto vertical = [&](double a) { return math_f64::pattern_power(v_shape, v_k, 0.5 * vbw, v_cheb, a); };
    const double half_pi = 0.5 * kPi;
    double width_h = 0.0, width_v = 0.0;
    if (line_array) {
        width_h = integrate([&](double u) { return horizontal(std::asin(u)); }, -1.0, 1.0, steps_for(hbw));
        width_v = integrate(vertical, -half_pi, half_pi, steps_for(vbw));
    } else {
        width_h = integrate(horizontal, -half_pi, half_pi, steps_for(hbw));
        width_v =
            integrate([&](double psi) { return vertical(psi) * std::cos(psi); }, -half_pi, half_pi, steps_for(vbw));
    }
    return std::max(10.0 * std::log10(4.0 * kPi / (width_h * width_v)), 0.0);
}

void resolve_noise_floor(Plan& p) {
    const SonarConfig& c = p.config;
    p.noise = c.noise_terms(); // finite for every config that validates (noise_floor_test.cpp)
    p.beam_noise.assign(p.beams, 0.0f);
    p.beam_floor_db.assign(p.beams, p.noise.floor_db());
    for (std::uint32_t j = 0; j < p.beams; ++j) {
        // A line array's beam steered to theta is a cone as wide in sine as at broadside, so 1 / cos(theta)
        // wider in angle: its solid angle grows by that and DI falls by 10 log10(1 / cos theta) (never below
        // an omnidirectional 0 dB).
        const double di = p.line_array ? std::max(p.noise.directivity_index_db +
                                                      10.0 * std::log10(std::max(std::cos(p.beam_angle_rad[j]), 1e-6)),
                                                  0.0)
                                       : p.noise.directivity_index_db;
        p.beam_floor_db[j] = p.noise.noise_level_db - di;
        // The element pattern scales the sea's noise in beam j as it does an echo from the beam's direction
        // (the pattern is broad against the beam's): the floor falls with it, and the SNR stays.
        if (p.element_k > 0.0)
            p.beam_floor_db[j] +=
                10.0 * std::log10(std::max(math_f64::element_power(p.element_k, std::sin(p.beam_angle_rad[j])), 1e-30));
        if (p.effects.ambient_noise) p.beam_noise[j] = static_cast<float>(std::pow(10.0, p.beam_floor_db[j] / 10.0));
    }
}

NoiseTerms SonarConfig::noise_terms() const {
    NoiseTerms t;
    t.band_hz = receive_band_hz(*this);
    t.noise_level_db = noise_level_db >= 0.0
                           ? noise_level_db
                           : band_noise_level_db(frequency_hz, t.band_hz, wind_speed_mps, shipping_activity);
    t.directivity_index_db = directivity_index_db >= 0.0
                                 ? directivity_index_db
                                 : beam_directivity_index_db(*this, resolves_to_line_array(*this, nullptr));
    return t;
}

} // namespace vksonar
