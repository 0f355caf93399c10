// Every GPU-vs-CPU tolerance in one place, each with its reason. tests/README.md lists them.
#pragma once

namespace vksonar::testing {

// Depth: lavapipe snaps vertices to 1/256 pixel (8 sub-pixel bits) and evaluates edge functions in
// fixed point; the CPU rasterizer evaluates them in double at the exact pixel centre. A pixel whose
// centre lies within ~1/256 px of a triangle edge can therefore be covered on one side only, or by
// the neighbouring triangle. That is a band ~1/128 px wide along every silhouette and occlusion
// edge: a few per mille of the hit pixels in the bundled scenes. 1% leaves headroom for
// tessellated cylinders and spheres, whose silhouettes are long for their area.
constexpr double kDepthEdgePixelBudget = 0.01;
// Where both backends cover a pixel with the same surface, view z agrees to float rounding of the
// interpolated z_ndc: reversed-Z float has ~2^-24 relative precision near d ~ 1e-2..1, and the
// depth -> z inversion amplifies it by up to far/near ~ 100: 1e-4 relative.
constexpr double kDepthInteriorRelTol = 1e-4;
// In metres: the same bound on the slant range, at most 1e-4 x range_max (4 mm at 40 m).

// Embedding, a host depth image in standard Z (d = 0 at near, 1 at far, D32 float): near d = 1 a
// float step is 2^-24, and z = n / (z_a + z_b d) turns one step into a relative z step of
// (f - n) / f * z / n * 2^-24, i.e. 4.8e-5 at 40 m with the example engine's n = 5 cm, f = 200 m.
// That is the precision an engine gives away with standard Z, not an error of vksonar. The host's
// rasterizer interpolates d with a few ulps of error (largest interior difference measured against the
// reversed-Z standalone render: 3.5 ulps on lavapipe, 3.7 on an NVIDIA H100), so for a standard-Z host
// the interior tolerance grows by 8 host depth ulps: twice what was seen.
constexpr double kHostStandardZUlps = 8;

// Normals from identical depth: same formulas, same order; the only differences are the float
// results of sqrt/atan in the driver vs libm (a few ulp), amplified by the cross product of two
// nearly parallel tangents at grazing incidence. 0.05 deg is well below the Sobel's own error.
constexpr double kNormalAngleTolDeg = 0.05;
// Pixels over it on a GPU (tests/stages/normals_test.cpp: one unexplained pixel on an H200).
constexpr double kNormalGpuOverBudget = 1e-5;
constexpr double kNormalCosTol = 1e-3;

// Geometric normals (normal_method = geometric). The CPU takes the cross of a triangle's edges in
// double; the GPU the cross of dFdx, dFdy of the interpolated clip-linear position in float: each
// derivative is a difference of two interpolated values of magnitude ~w (up to 40 m) that differ by
// ~2w / slice_columns, so it carries a relative error of ~1e-5 (more where the two derivatives are
// nearly parallel, at grazing incidence). A tilted plane (every pixel, edges included, 3 slices):
// measured 4e-6 deg / cos 1.6e-7 on the CPU, 3.2e-3 deg / cos 2.0e-5 on lavapipe. The cos tolerance
// also covers the plane's own tilt error from float vertices: a strip 1 cm wide whose vertices are
// rounded to float near 10 m (ulp 9.5e-7 m) tilts by ~1e-4 rad (measured: cos error 1.2e-5).
constexpr double kGeometricPlaneAngleTolDeg = 0.02;
constexpr double kGeometricPlaneCosTol = 2e-4;
// Bundled scenes, GPU vs CPU, where both backends cover the pixel with the same material: measured
// up to 1.0e-2 deg and |d cos| 9.4e-5 on lavapipe (harbour). Pixels beyond this are triangle-edge
// pixels that the neighbouring triangle won on one backend (the depth test's sub-pixel band, now
// along internal mesh edges too, where the depth agrees but the face normal is the neighbour's:
// measured 24-47 pixels, 0.03-0.06% of the hits); they share kDepthEdgePixelBudget.
constexpr double kGeometricAngleTolDeg = 0.05;
constexpr double kGeometricCosTol = 5e-4;

// Echo from identical inputs: exp/sin/sqrt differ by a few ulp between LLVM's vectorized versions
// and libm; near a beam-pattern null the pattern value is a small difference of larger numbers, so
// the relative error is measured against max(value, 1e-6 x frame peak).
constexpr double kEchoRelTol = 1e-4;
constexpr double kEchoRelFloor = 1e-6;
// The vertical pattern's power b (1 on its axis) from identical inputs, absolute, as a share of the
// pixel's echo without the pattern (E0 = E / b). The depth pass covers the pattern out to its first null
// (src/core/plan_grid.cpp), where b -> 0 and no relative tolerance holds: b is a function of
// x = k sin(psi), psi from atan2, and the driver's sin/atan2 put ~2e-6 relative error into x, so b
// carries an absolute error |db/dx| x 2e-6, which falls only as sqrt(b) towards a null (up to ~2e-6 on
// the main lobe's flank, where b ~ 0.5 keeps it inside kEchoRelTol). Largest measured on lavapipe where the relative
// tolerance fails: sinc (bundled scenes) 1.7e-7 of E0 at b = 1.7e-3; -35 dB chebyshev 1.3e-6 at
// b = 9.4e-3 (its main lobe's skirt, cosh(sqrt((A - x)(A + x))) with A - x small). A pixel passes if it
// agrees within kEchoRelTol of its value or within kVerticalPatternAbsTol x E0: 5e-6, -53 dB of the
// beam's peak, about 4x the largest measured.
constexpr double kVerticalPatternAbsTol = 5e-6;
constexpr double kRangeAbsTolM = 1e-4; // slant range of up to 120 m in float: ulp 7.6e-6 m

// Beamform from identical echo: the same sums in the same order in float, no fused multiply-add on
// either side (`precise` in the shaders). Bin coordinates multiply by a host-rounded 1 / bin width, so
// they are bit-identical on any Vulkan device. What still differs is the footprint kernel's own
// arithmetic: its exp, log, square root and divisions, which Vulkan lets a device compute a few ulps
// from the correctly rounded value (exp 3 + 2|x| ulp, log 3 ulp or 2^-21 absolute, division 2.5 ulp).
// lavapipe's happen to match glibc's closely: measured at most 7.2e-7 there (profiles, every pass and
// part of BeamformGpuCpuParts), so lavapipe keeps 1e-5 relative, as a regression check of the order
// of the sums. On a GPU a last-bit change moves a narrow footprint's share of its edge bins: the CPU
// kernel with its divisions and square roots moved by 2 ulps (and exp, log by their bounds) changes the
// scan by up to 1e-5. An NVIDIA H100 (c0d785f): profiles 3.3e-5, beam profiles 2.5e-5, scan 1.5e-6; in
// dB 6.9e-4 at most, in a cell above the noise floor but far below the peak (the relative error has a
// floor of 1e-6 x peak, the dB error none). So on a GPU: 1e-4 relative, 5e-3 dB, 3 and 7 times those.
// (Before the footprint was measured from the pixel's own bin, sonar_kernels.h RangeSpread::origin, the
// H100's profiles were 1.4e-4 to 6.3e-4 apart; before the bin coordinates were exact, 3.6e-4.)
constexpr double kBeamformRelTol = 1e-5;
constexpr double kBeamformGpuRelTol = 1e-4;
constexpr double kBeamformGpuDbTol = 5e-3;
constexpr double kBeamformRelFloor = 1e-6;

// Whole frame: the depth edge pixels above move energy between neighbouring cells. A cell fed by
// a few hundred pixels changes by ~1/100 of its energy per flipped pixel; cells above the noise
// floor that differ by more than 1 dB must stay under 2% of the cells.
constexpr double kFrameDbTol = 1.0;
constexpr double kFrameCellBudget = 0.02;

} // namespace vksonar::testing
