// The horizontal pattern out of focus (docs/pipeline.md, "Focus"): the aperture's pattern with the
// quadratic phase a beam that is not focused at the echo's range leaves across it. Internal to src/core.
#pragma once

#include <cstdint>
#include <vector>

#include "core/plan.h"

namespace vksonar::plan_steps {

// The defocus phase at the aperture's ends per (1 / r - 1 / F), in radians times metres: pi L^2 / (4 lambda)
// with L = k lambda / pi the aperture the pattern constant k implies (x = k u across s in [-1, 1]).
double focus_phase_per_inverse_metre(const Plan& p);

// The most defocus vksonar tabulates (DefocusedPattern's cost grows as its cube): an unfocused 1 deg beam at
// 750 kHz reaches it at 6 cm, the ARIS's 0.25 deg at 3 MHz at 25 cm.
constexpr double kMaxFocusPhase = 64.0;

// Step (after plan_effects): the focus bands of the range bins, Plan::near_band_of_bin and near_band_phase.
// One band of phase 0 with beam_focus dynamic or no near kernel to apply them (near_kernel: the horizontal
// pattern on, with a kernel past the tent); an error where a bin's phase passes kMaxFocusPhase.
Result<void> plan_focus_bands(Plan& p, bool near_kernel);

// Whether the plan's bands defocus the pattern (else one band of phase 0: the far-field pattern).
inline bool out_of_focus(const Plan& p) {
    return p.near_band_phase.back() > 0.0;
}

// How far out in x a band of phase phi keeps its own pattern (docs/pipeline.md "Focus"): kTailPhases phi +
// 3 pi. The defocused lobes fall as the aperture ends' waves, |A|^2 ~ (1/(x - 2 phi)^2 + 1/(x + 2 phi)^2) / 4,
// within 1.1 dB of the far field's 1 / (2 x^2) from x = 7 phi on: past it the far grid's far-field lobes
// take over with no visible step. Every band of a focus other than dynamic, phase 0 too (3 pi).
constexpr double kTailPhases = 7.0;
double focus_reach_x(double phase);

// |A(x, phi)|^2 of the aperture (sinc: uniform, hann: raised cosine over s in [-1, 1]),
// A = int w(s) exp(i (x s - phi s^2)) ds / int w(s) ds, tabulated for 0 <= phi <= phi_max (rows as
// below, linear between them) and |x| up to 2 phi_max + kTail (cubic in x); past that, the aperture
// ends' waves (sinc, four terms) or the far-field pattern (hann, below -70 dB there).
class DefocusedPattern {
public:
    static constexpr double kRowStep = 0.02;          // phi: rows 0.02 rad apart up to 4 rad,
    static constexpr std::uint32_t kLinearRows = 200; // then 0.5 % apart (the pattern's features scale
    static constexpr double kRowRatio = 1.005;        // with phi there); linear between rows
    static constexpr double kXStep = 0.1;             // x: 31 samples a lobe, Catmull-Rom between them
    static constexpr double kTail = 48.0;

    DefocusedPattern(std::uint32_t shape, double phi_max);
    double power(double x, double phi) const;

private:
    static double row_phase(std::uint32_t row);
    static double row_at(double phi); // fractional row of phi

    std::uint32_t shape_;
    double x_max_ = 0.0;
    std::uint32_t rows_ = 0, samples_ = 0;
    std::vector<double> table_; // rows_ * samples_, sample i at x = (i - 1) kXStep (i = 0 mirrors x = kXStep)
};

} // namespace vksonar::plan_steps
