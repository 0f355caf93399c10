// The horizontal pattern out of focus (docs/pipeline.md, "Focus").
//
// A beam formed from an aperture of length L hears a point at range r through the path lengths to each
// place x on it, r - x u + x^2 cos^2(theta) / (2 r) to second order (u: the direction's sine along the
// aperture; theta: its steering angle, 0 for a lens or a planar beam). Focused at F, the beamformer takes
// x^2 cos^2(theta) / (2 F) off: at F (or at every range, beam_focus dynamic) the pattern is the far-field
// one, elsewhere a quadratic phase phi s^2 is left across the aperture (s = 2 x / L in [-1, 1]),
//   phi = pi L^2 / (4 lambda) |1 / r - 1 / F| cos^2(theta),
// and the pattern is |A(x, phi)|^2 with x = k u as in the far field (k = pi L / lambda, the pattern
// constant). phi = pi / 4 at r = L^2 / lambda for an unfocused array: the far-field distance's rule.
#include "core/plan_focus.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <string>

#include "core/angles.h"
#include "core/plan_steps.h"
#include "core/sonar_math.hpp"

namespace vksonar::plan_steps {

namespace {

// The bands' ladder in phi: steps of 0.1 rad, and of 6 % past 1.67 rad. The pattern moves with phi as
// about 0.18 phi dphi at its peak while phi is small, and as the width of a flat top 4 phi wide when it is
// large: a bin at most half a step from its band's phi is within about 0.13 dB of its own pattern.
constexpr double kBandStep = 0.1;
constexpr double kBandRatio = 0.06;

// Gauss-Legendre nodes and weights on [0, 1] (Newton on P_n from the usual first guess).
void gauss_legendre(std::uint32_t n, std::vector<double>& node, std::vector<double>& weight) {
    node.resize(n);
    weight.resize(n);
    for (std::uint32_t i = 0; i < n; ++i) {
        double z = std::cos(kPi * (i + 0.75) / (n + 0.5));
        double dp = 1.0;
        for (int iteration = 0; iteration < 100; ++iteration) {
            double p0 = 1.0, p1 = 0.0;
            for (std::uint32_t m = 1; m <= n; ++m) { // P_m from P_{m-1}, P_{m-2}
                const double p2 = p1;
                p1 = p0;
                p0 = ((2.0 * m - 1.0) * z * p1 - (m - 1.0) * p2) / m;
            }
            dp = n * (z * p0 - p1) / (z * z - 1.0);
            const double step = p0 / dp;
            z -= step;
            if (std::abs(step) < 1e-15) break;
        }
        node[i] = 0.5 * (1.0 - z);
        weight[i] = 1.0 / ((1.0 - z * z) * dp * dp); // 2 / ((1 - z^2) P'^2), halved for [0, 1]
    }
}

} // namespace

double focus_phase_per_inverse_metre(const Plan& p) {
    const double lambda = p.config.sound_speed_mps / p.config.frequency_hz;
    const double aperture = p.hpattern_k * lambda / kPi;
    return kPi * aperture * aperture / (4.0 * lambda);
}

Result<void> plan_focus_bands(Plan& p, bool near_kernel) {
    p.near_bands = 1;
    p.near_band_of_bin.assign(p.bins, 0);
    p.near_band_phase.assign(1, 0.0);
    const SonarConfig& c = p.config;
    if (c.beam_focus == BeamFocus::dynamic || !near_kernel || p.bins == 0) return {};
    const double scale = focus_phase_per_inverse_metre(p);
    const double inverse_focus = c.beam_focus == BeamFocus::fixed ? 1.0 / c.focus_range_m : 0.0;
    std::vector<double> phase(p.bins);
    double phase_max = 0.0, worst_range = 0.0;
    for (std::uint32_t k = 0; k < p.bins; ++k) {
        phase[k] = scale * std::abs(1.0 / p.bin_range_m[k] - inverse_focus);
        if (!(phase[k] <= phase_max)) { // NaN and infinity too
            phase_max = phase[k];
            worst_range = p.bin_range_m[k];
        }
    }
    if (!(phase_max <= kMaxFocusPhase)) {
        // The remedy on the worst bin's side of the focus: nearer than F the phase falls as r grows (range_min
        // up to where it is kMaxFocusPhase); beyond F it grows towards scale / F (range_max down).
        const bool fixed = c.beam_focus == BeamFocus::fixed;
        const double allowed = kMaxFocusPhase / scale; // |1/r - 1/F| at most this
        std::string remedy;
        if (!fixed || worst_range < c.focus_range_m)
            remedy = "raise range_min to " + fmt(1.0 / (inverse_focus + allowed)) + " m" +
                     (fixed ? " (or set focus_range nearer)" : "");
        else
            remedy = "lower range_max to " + fmt(1.0 / (inverse_focus - allowed)) + " m (or set focus_range further)";
        if (!(phase_max < std::numeric_limits<double>::infinity())) remedy = "set focus_range within the range window";
        return make_error(ErrorCode::invalid_argument,
                          std::string("config: beam_focus = ") + (fixed ? "fixed" : "none") +
                              ": the defocus phase pi L^2 / (4 lambda) |1/r - 1/F| reaches " + fmt(phase_max) +
                              " rad at r = " + fmt(worst_range) +
                              " m (L = " + fmt(p.hpattern_k * c.sound_speed_mps / c.frequency_hz / kPi) + " m" +
                              (fixed ? ", focus_range = " + fmt(c.focus_range_m) + " m" : std::string()) +
                              "), past the " + fmt(kMaxFocusPhase) + " rad vksonar tabulates: " + remedy);
    }
    std::vector<double> ladder{0.0};
    while (ladder.back() < phase_max)
        ladder.push_back(ladder.back() + std::max(kBandStep, kBandRatio * ladder.back()));
    std::vector<std::uint32_t> rung(p.bins);
    std::vector<bool> used(ladder.size(), false);
    for (std::uint32_t k = 0; k < p.bins; ++k) {
        const auto above = std::lower_bound(ladder.begin(), ladder.end(), phase[k]);
        std::size_t r = static_cast<std::size_t>(above - ladder.begin());
        if (r == ladder.size() || (r > 0 && phase[k] - ladder[r - 1] < ladder[r] - phase[k])) --r;
        rung[k] = static_cast<std::uint32_t>(r);
        used[r] = true;
    }
    std::vector<std::uint32_t> band_of_rung(ladder.size(), 0);
    p.near_band_phase.clear();
    for (std::size_t r = 0; r < ladder.size(); ++r)
        if (used[r]) {
            band_of_rung[r] = static_cast<std::uint32_t>(p.near_band_phase.size());
            p.near_band_phase.push_back(ladder[r]);
        }
    p.near_bands = static_cast<std::uint32_t>(p.near_band_phase.size());
    for (std::uint32_t k = 0; k < p.bins; ++k)
        p.near_band_of_bin[k] = band_of_rung[rung[k]];
    return {};
}

double focus_reach_x(double phase) {
    return kTailPhases * phase + 3.0 * kPi;
}

double DefocusedPattern::row_phase(std::uint32_t row) {
    return row <= kLinearRows ? row * kRowStep : kLinearRows * kRowStep * std::pow(kRowRatio, row - kLinearRows);
}

double DefocusedPattern::row_at(double phi) {
    if (phi <= kLinearRows * kRowStep) return phi / kRowStep;
    return kLinearRows + std::log(phi / (kLinearRows * kRowStep)) / std::log(kRowRatio);
}

DefocusedPattern::DefocusedPattern(std::uint32_t shape, double phi_max) : shape_(shape) {
    phi_max = std::max(phi_max, 0.0);
    x_max_ = 2.0 * phi_max + kTail;
    rows_ = static_cast<std::uint32_t>(std::ceil(row_at(phi_max))) + 2; // at least two
    samples_ = static_cast<std::uint32_t>(std::ceil(x_max_ / kXStep)) + 4;
    // exp(i (x s - phi s^2)) turns through at most x_max + 2 phi_max radians over [0, 1]: Gauss-Legendre
    // with 0.7 nodes a radian and 24 more is exact to rounding there.
    const auto nodes = static_cast<std::uint32_t>(std::ceil(0.7 * (x_max_ + 2.0 * phi_max))) + 24;
    std::vector<double> s, g;
    gauss_legendre(nodes, s, g);
    // The aperture is even: A = int_0^1 w(s) cos(x s) exp(-i phi s^2) ds / int_0^1 w(s) ds.
    std::vector<double> w(nodes);
    double norm = 0.0;
    for (std::uint32_t n = 0; n < nodes; ++n) {
        w[n] = g[n] * (shape == shared::kPatternHann ? 0.5 * (1.0 + std::cos(kPi * s[n])) : 1.0);
        norm += w[n];
    }
    std::vector<double> cosine(std::size_t(samples_) * nodes);
    for (std::uint32_t i = 0; i < samples_; ++i)
        for (std::uint32_t n = 0; n < nodes; ++n)
            cosine[std::size_t(i) * nodes + n] = std::cos((double(i) - 1.0) * kXStep * s[n]);
    table_.resize(std::size_t(rows_) * samples_);
    std::vector<double> re(nodes), im(nodes);
    for (std::uint32_t row = 0; row < rows_; ++row) {
        const double phi = row_phase(row);
        for (std::uint32_t n = 0; n < nodes; ++n) {
            re[n] = w[n] / norm * std::cos(phi * s[n] * s[n]);
            im[n] = -w[n] / norm * std::sin(phi * s[n] * s[n]);
        }
        for (std::uint32_t i = 0; i < samples_; ++i) {
            const double* c = cosine.data() + std::size_t(i) * nodes;
            double a = 0.0, b = 0.0;
            for (std::uint32_t n = 0; n < nodes; ++n) {
                a += re[n] * c[n];
                b += im[n] * c[n];
            }
            table_[std::size_t(row) * samples_ + i] = a * a + b * b;
        }
    }
}

double DefocusedPattern::power(double x, double phi) const {
    x = std::abs(x);
    phi = std::max(phi, 0.0);
    if (x >= x_max_) {
        if (shape_ != shared::kPatternSinc) return math_f64::aperture_pattern_power(shape_, 1.0, 0.0, x);
        // Past the geometric shadow (x - 2 phi >= kTail) the aperture's two ends alone, by parts:
        // int e^{i psi} ds = [e^{i psi} (-i/p + 2 phi/p^3 + 12 i phi^2/p^5 - 120 phi^3/p^7)] at s = +-1, with
        // psi = x s - phi s^2 and p = psi' = x - 2 phi s; each term (2n + 1) 2 phi / p^2 of the one before
        // (at most 0.39 here, at 64 rad), the first left out about 1e-3 of the sum. sin x / x at phi = 0.
        auto ends = [&](double p) {
            const double p2 = p * p, p3 = p2 * p, p5 = p3 * p2, p7 = p5 * p2;
            return std::complex<double>(2.0 * phi / p3 - 120.0 * phi * phi * phi / p7,
                                        -1.0 / p + 12.0 * phi * phi / p5);
        };
        const std::complex<double> a =
            0.5 * (std::polar(1.0, x - phi) * ends(x - 2.0 * phi) - std::polar(1.0, -x - phi) * ends(x + 2.0 * phi));
        return std::norm(a);
    }
    // Linear between the two rows about phi, Catmull-Rom through four samples about x in each.
    const double rows_at = std::min(row_at(phi), double(rows_ - 1));
    const auto row = std::min(static_cast<std::uint32_t>(rows_at), rows_ - 2);
    const double g = std::clamp((phi - row_phase(row)) / (row_phase(row + 1) - row_phase(row)), 0.0, 1.0);
    const double t = x / kXStep + 1.0;
    const auto i = std::min(static_cast<std::uint32_t>(t), samples_ - 3); // samples i - 1 .. i + 2
    const double f = t - i;
    auto at_row = [&](std::uint32_t r) { // Catmull-Rom through v[0..3] at f between v[1] and v[2]
        const double* v = table_.data() + std::size_t(r) * samples_ + i - 1;
        return v[1] + 0.5 * f *
                          (v[2] - v[0] +
                           f * (2.0 * v[0] - 5.0 * v[1] + 4.0 * v[2] - v[3] + f * (3.0 * (v[1] - v[2]) + v[3] - v[0])));
    };
    const double value = (1.0 - g) * at_row(row) + g * at_row(row + 1);
    return std::max(value, 0.0);
}

} // namespace vksonar::plan_steps
