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

// Step (after plan_range_window and plan_horizontal_pattern): the focus bands of the range bins,
// Plan::near_band_of_bin and near_band_phase. One band of phase 0 with beam_focus dynamic.
void plan_focus_bands(Plan& p);

// The reach, in the separation unit (sidelobe_reach), that the most defocused band's pattern needs: its
// spread over x = +-2 phi and three lobes past it. 0 with one band of phase 0.
double focus_reach_units(const Plan& p);

// |A(x, phi)|^2 of the aperture (sinc: uniform, hann: raised cosine over s in [-1, 1]),
// A = int w(s) exp(i (x s - phi s^2)) ds / int w(s) ds, tabulated for 0 <= phi <= phi_max (rows of
// kRowStep, linear between them) and |x| up to 2 phi_max + kTail (cubic in x); past that, the aperture
// edges' closed form (sinc) or the far-field pattern (hann, below -70 dB there).
class DefocusedPattern {
public:
    static constexpr double kRowStep = 0.02; // phi: linear between rows
    static constexpr double kXStep = 0.1;    // x: 31 samples a lobe, Catmull-Rom between them
    static constexpr double kTail = 48.0;

    DefocusedPattern(std::uint32_t shape, double phi_max);
    double power(double x, double phi) const;

private:
    std::uint32_t shape_;
    double x_max_ = 0.0;
    std::uint32_t rows_ = 0, samples_ = 0;
    std::vector<double> table_; // rows_ * samples_, sample i at x = (i - 1) kXStep (i = 0 mirrors x = kXStep)
};

} // namespace vksonar::plan_steps
