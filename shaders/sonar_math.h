// The sonar model's formulas, written once for GLSL and C++.
//
// No include guard on purpose: C++ includes this file twice, with REAL = float and REAL = double,
// inside namespaces vksonar::math_f32 / vksonar::math_f64 (see src/core/sonar_math.hpp). GLSL
// includes it once with REAL = float. Only scalar code that is valid in both languages goes here:
// REAL(x) casts, sqrt/sin/cos/exp/pow/abs/min/max, VKS_ATAN2 for the two-argument arctangent, and the
// named constants of sonar_shared.h (never their literal values: src/core/plan.cpp maps the public
// enums onto those names, with static_asserts).
//
// Geometry conventions (README, "Frames, units and outputs"): sonar frame x forward, y left (port), z up.
// A slice camera looks along its centre azimuth; pixel (column c, row j) of a slice with W columns
// and H rows has focal-normalized coordinates u (to the right) and v (downward):
//   u = (2 (c + 0.5) / W - 1) tan_half_h,  v = (2 (j + 0.5) / H - 1) tan_half_v
// ray (camera frame, x right, y down, z forward) = (u, v, 1).

#ifndef REAL
#error "define REAL (float or double) before including sonar_math.h"
#endif
#ifdef __cplusplus
#define VKS_FN inline
#else
#define VKS_FN
#endif

// Focal-normalized pixel-centre coordinate of index i of n across [-tan_half, tan_half].
VKS_FN REAL pixel_coord(uint i, uint n, REAL tan_half) {
    return (REAL(2) * (REAL(i) + REAL(0.5)) / REAL(n) - REAL(1)) * tan_half;
}

// Slice of pixel column c, c / slice_columns, by a multiply with inv_slice_columns = 1 / slice_columns
// rounded to REAL: a GPU has no vector integer divide (lavapipe runs one scalar divide per lane).
// Exact for slice_columns < 2^17 and c < 2^23: the quotient's fraction lies in [0.5 / W, 1 - 0.5 / W]
// and the two roundings move it by < 16 * 2^-23 (tests/stages/depth_test.cpp checks every column).
VKS_FN uint slice_of_column(uint c, REAL inv_slice_columns) {
    return uint((REAL(c) + REAL(0.5)) * inv_slice_columns);
}

// The view of pixel column c: the `slices` views slice_columns wide, then the tier views tier_columns
// wide (Plan::tier_columns; inv_*: the widths' reciprocals, as slice_of_column takes them).
VKS_FN uint view_of_pixel_column(uint c, uint slices, uint slice_columns, REAL inv_slice_columns,
                                 REAL inv_tier_columns) {
    uint main_columns = slices * slice_columns;
    return c < main_columns ? slice_of_column(c, inv_slice_columns)
                            : slices + slice_of_column(c - main_columns, inv_tier_columns);
}

// The first pixel column of view `view` and its width, in the same layout.
VKS_FN uint first_column_of_view(uint view, uint slices, uint slice_columns, uint tier_columns) {
    return view < slices ? view * slice_columns : slices * slice_columns + (view - slices) * tier_columns;
}
VKS_FN uint columns_of_view(uint view, uint slices, uint slice_columns, uint tier_columns) {
    return view < slices ? slice_columns : tier_columns;
}

// Exact solid angle of a pixel of size du x dv (focal-normalized) centred at (u, v).
VKS_FN REAL pixel_solid_angle(REAL u, REAL v, REAL du, REAL dv) {
    REAL q = REAL(1) + u * u + v * v;
    return du * dv / (q * sqrt(q));
}

// View-space z (metres along the slice's optical axis) from reversed-Z depth d in (0, 1].
VKS_FN REAL view_z_from_depth(REAL d, REAL depth_a, REAL depth_b) {
    return depth_a / (d - depth_b);
}

// Slant range of a pixel at view-space z.
VKS_FN REAL slant_range(REAL view_z, REAL u, REAL v) {
    return view_z * sqrt(REAL(1) + u * u + v * v);
}

// Azimuth (positive to port) of a pixel column inside a slice centred at slice_azimuth.
VKS_FN REAL pixel_azimuth(REAL slice_azimuth, REAL u) {
    return slice_azimuth - atan(u);
}

// Elevation (positive up) of a pixel ray.
VKS_FN REAL pixel_elevation(REAL u, REAL v) {
    return VKS_ATAN2(-v, sqrt(REAL(1) + u * u));
}

// sinc(x) = sin(x) / x, exact 1 at 0 and without 0/0 near it.
VKS_FN REAL sinc_of(REAL x) {
    REAL ax = abs(x);
    if (ax < REAL(1e-4)) {
        return REAL(1) - x * x / REAL(6);
    }
    return sin(x) / x;
}

// Beam pattern power (1 on axis) at angle a off the beam axis.
// k: pattern constant computed on the host so that the power is 0.5 at +-beamwidth/2
// (sinc/hann/chebyshev: k = x_3dB / sin(bw/2); gaussian: k = ln 2 / (bw/2)^2); box: half_width.
// chebyshev_a: A = acosh(R) of the chebyshev pattern (R = main-lobe / side-lobe amplitude), whose
// amplitude is cosh(sqrt(A^2 - x^2)) / cosh(A) in the main lobe (x < A) and cos(sqrt(x^2 - A^2)) / cosh(A)
// beyond it: side lobes of exactly 1 / R, the first null at x = sqrt(A^2 + (pi/2)^2).
// The aperture patterns (sinc, hann, chebyshev) depend on the angle only through sin(a): their power
// from sin_a, for callers that have the sine as a ratio (view_elevation_sin) and need no arctangent.
// aperture_pattern_amplitude is the signed amplitude (the aperture's Fourier transform, 1 on axis), whose
// square the power is; the noise stage's grain filter (core/plan_grain.cpp) needs its sign.
VKS_FN REAL aperture_pattern_amplitude(uint shape, REAL k, REAL chebyshev_a, REAL sin_a) {
    REAL x = k * sin_a;
    if (shape == kPatternChebyshev) {
        // (A - x)(A + x), not A^2 - x^2: near x = A (the edge of the main lobe, and past it towards the
        // first null) the squares cancel and float would lose most of the difference's digits.
        REAL d = (chebyshev_a - x) * (chebyshev_a + x);
        REAL amp_cheb = d >= REAL(0) ? cosh(sqrt(d)) : cos(sqrt(-d));
        return amp_cheb / cosh(chebyshev_a);
    }
    REAL amp = sinc_of(x);
    if (shape == kPatternHann) {                   // sinc(x) / (1 - (x/pi)^2), removable singularity at x = pi
        REAL t = x / REAL(3.14159265358979323846); // not kPi: a float
        REAL den = REAL(1) - t * t;
        if (abs(den) < REAL(1e-4)) {
            amp = REAL(0.5);
        } else {
            amp = amp / den;
        }
    }
    return amp;
}

VKS_FN REAL aperture_pattern_power(uint shape, REAL k, REAL chebyshev_a, REAL sin_a) {
    REAL amp = aperture_pattern_amplitude(shape, k, chebyshev_a, sin_a);
    return amp * amp;
}

VKS_FN REAL pattern_power(uint shape, REAL k, REAL half_width, REAL chebyshev_a, REAL a) {
    if (shape == kPatternBox) {
        return abs(a) <= half_width ? REAL(1) : REAL(0);
    }
    if (shape == kPatternGaussian) {
        return exp(-k * a * a);
    }
    return aperture_pattern_power(shape, k, chebyshev_a, sin(a));
}

// The combined sonar equation per pixel, without the source level (added on the host in dB):
//   E = 10^(mu/10) * f(theta) * Omega * r^-2 * 10^(-2 alpha r / 10) * b_v(psi)^2
// where f = cos(theta) for Lambert (so grazing goes smoothly to 0 and never divides by zero).
// Spreading off keeps the footprint r^2 Omega but drops the r^-4 two-way loss.
VKS_FN REAL echo_energy(REAL backscatter_linear, REAL scatter_factor, REAL solid_angle, REAL range_m,
                        REAL alpha_db_per_m, REAL vertical_power, bool spreading, bool absorption) {
    REAL e = backscatter_linear * scatter_factor * solid_angle * vertical_power;
    if (spreading) {
        e = e / (range_m * range_m);
    } else {
        e = e * range_m * range_m;
    }
    if (absorption) {
        // 10^(-2 alpha r / 10) = exp(-2 alpha r ln10 / 10); underflows to exactly 0, never NaN
        e = e * exp(-REAL(0.2302585092994046) * alpha_db_per_m * range_m * REAL(2));
    }
    return e;
}

// Facet (Kirchhoff, geometric-optics) term of a rough interface with Gaussian slopes of rms m, as a
// multiple of its value at normal incidence and divided by cos(theta) like every f:
//   exp(-tan^2(theta) / (2 m^2)) / cos^5(theta),  c = cos(theta), inv_two_slope_sq = 1 / (2 m^2).
// Exactly 0 where the exponential is below e^-80 (that also covers c = 0 and NaN), so the cos^5
// never divides by a number near zero: with m <= 1 a non-zero value needs c > 0.078.
// sin^2 as (1 - c)(1 + c): 1 - c is exact for c >= 0.5, where 1 - c^2 would cancel (float, c = 0.999:
// 3e-5 relative error in tan^2 against ~1e-7).
VKS_FN REAL specular_facet(REAL c, REAL inv_two_slope_sq) {
    REAL c2 = c * c;
    REAL t = (REAL(1) - c) * (REAL(1) + c) * inv_two_slope_sq; // tan^2 / (2 m^2), times c^2
    if (!(t < REAL(80) * c2)) {
        return REAL(0);
    }
    return exp(-t / c2) / (c2 * c2 * c);
}

// Scattering factor f(theta) = s(theta) / (10^(mu/10) cos(theta)) of a material model (kScatter*) at
// cosine of incidence c: the factor that multiplies 10^(mu/10) Omega r^-2 in echo_energy().
VKS_FN REAL scatter_factor(uint model, REAL c, REAL specular_ratio, REAL inv_two_slope_sq) {
    if (model == kScatterLambert) {
        return c;
    }
    if (model == kScatterRough) { // lambert + facet term
        return c + specular_ratio * specular_facet(c, inv_two_slope_sq);
    }
    return REAL(1); // kScatterConstant
}

// Which share of a column's range profile beam j adds in the resample (docs/pipeline.md §4), for a
// column assigned to beam `column_beam`: 1 = column_weight (its own beam), 2 = 1 - column_weight (the
// next beam; on a full circle beam 0 follows the last one, across the seam), 0 = none. Written without
// `% beams`: lavapipe would divide once per lane.
VKS_FN uint resample_share(uint column_beam, uint j, uint beams, bool circular) {
    if (column_beam == j) {
        return 1u;
    }
    bool next = column_beam + 1u == j || (circular && column_beam + 1u == beams && j == 0u);
    return next ? 2u : 0u;
}

// Fractional range-bin coordinate: bin k covers [range_min + k w, range_min + (k+1) w). Takes 1 / w:
// a multiplication is correctly rounded on every Vulkan device, a division is not.
VKS_FN REAL range_bin_coord(REAL range_m, REAL range_min_m, REAL inv_bin_width_m) {
    return (range_m - range_min_m) * inv_bin_width_m;
}

// Two range steps along a column are steps over the same smooth surface if they go the same way and
// neither is more than twice the other. On a flat seabed seen at depression angle b with rows dB apart
// the ratio of consecutive steps is about 1 + 2 dB / b: 1.1 at 6 degrees with 0.3-degree rows, 2 only
// below b = 2 dB (a fraction of a degree). At an occlusion edge the step to the surface behind is many
// times the step along the surface in front, or goes the other way.
VKS_FN bool steps_agree(REAL s, REAL t) {
    REAL as = abs(s);
    REAL at = abs(t);
    return s * t > REAL(0) && as <= REAL(2) * at && at <= REAL(2) * as;
}

// Offset (m, signed) from a pixel's range r to its edge towards row neighbour q (range r_q, 0 = no hit):
// half the step to q if q lies on the same surface, else 0. Same surface: the step is within
// jump_rel * r (a surface facing the sonar), or it agrees (steps_agree) with the next step beyond q
// (r_beyond, the neighbour's own neighbour on that side) or with the step from the opposite neighbour
// (r_opposite) to r. The second rule keeps a grazing seabed whole where its range steps between rows
// are larger than the jump threshold (far out, or at a coarse row grid): with the threshold alone its
// pixels lose their footprint and each puts all its energy into one bin, leaving the bins between empty.
VKS_FN REAL footprint_edge_offset(REAL r_q, REAL r_beyond, REAL r, REAL r_opposite, REAL jump_rel) {
    if (!(r_q > REAL(0))) {
        return REAL(0);
    }
    REAL s = r_q - r;
    bool same = abs(s) <= jump_rel * r || (r_beyond > REAL(0) && steps_agree(s, r_beyond - r_q)) ||
                (r_opposite > REAL(0) && steps_agree(s, r - r_opposite));
    return same ? REAL(0.5) * s : REAL(0);
}

// The edge offset on a side without a neighbour on the pixel's surface, from the other side's offset
// `other` (half the step to that side's neighbour, range r_near; 0: none there either) and the range
// r_beyond of the neighbour's own neighbour: the other side mirrored (an edge pixel spans as far either
// way), scaled by how the steps change along the column where they agree (steps_agree: the ratio of the
// step to r_near to the step beyond it, within [0.5, 2]). A grazing seabed's row steps grow towards the
// horizon; mirrored, the last row before the depth pass's far plane (range_max) was a third too short on
// its far side and put +0.3 dB into the window's last bins at h = 1 m.
VKS_FN REAL footprint_missing_edge(REAL other, REAL r_near, REAL r_beyond, REAL r) {
    REAL s = r_near - r;
    REAL t = r_beyond - r_near;
    if (other != REAL(0) && r_beyond > REAL(0) && steps_agree(s, t)) {
        return -other * (s / t);
    }
    return -other;
}

// The pixel's range footprint [r + footprint_lo(a, b), r + footprint_hi(a, b)] from its two edge
// offsets a (towards the row above) and b (below), a missing side's already given by
// footprint_missing_edge: the range interval between its edges, and the pixel's own range in it (with
// neither side, the point r: the kernel widens it to a bin).
VKS_FN REAL footprint_lo(REAL a, REAL b) {
    return min(min(a, b), REAL(0));
}
VKS_FN REAL footprint_hi(REAL a, REAL b) {
    return max(max(a, b), REAL(0));
}

// The pixel's range extent across its column, from its row neighbours left and right (ranges r_left,
// r_right; 0 = no hit or the edge of the pixel's view): the offsets to those edges as
// footprint_edge_offset gives them (with no pixel beyond, the same surface by the jump threshold or the
// opposite step), a missing side mirrored. Returns (lo, hi), the extent's offsets from r (m), lo <= 0 <= hi.
// Where the range changes along a row as well as down a column (a pitched or rolled seabed, the nadir's
// bowl, a wall at a slant in azimuth) a pixel's echo spans both. Measured on the flat seabed's closed form
// (tests/hard_cases): with it the worst bin at h = 3-10 m, pitch 10-30 deg, is -0.04 dB, without it -0.16.
// It came with keeping footprints narrower than a bin (kMinFootprintBins): widening every one to a bin
// had smeared the seabed's sharp onset at the altitude (+0.33 to +0.41 dB in its bin at h = 1-3 m).
VKS_FN vec2 footprint_across(REAL r_left, REAL r, REAL r_right, REAL jump_rel) {
    REAL a = footprint_edge_offset(r_left, REAL(0), r, r_right, jump_rel);
    REAL b = footprint_edge_offset(r_right, REAL(0), r, r_left, jump_rel);
    REAL a2 = a != REAL(0) ? a : -b;
    REAL b2 = b != REAL(0) ? b : -a;
    return vec2(footprint_lo(a2, b2), footprint_hi(a2, b2));
}

// sinh(y) / y, without 0/0 at y = 0 or cancellation near it (series below |y| = 0.5: error < 1e-9).
VKS_FN REAL sinhc_of(REAL y) {
    if (abs(y) < REAL(0.5)) {
        REAL y2 = y * y;
        return REAL(1) + y2 / REAL(6) * (REAL(1) + y2 / REAL(20) * (REAL(1) + y2 / REAL(42)));
    }
    return (exp(y) - exp(-y)) / (REAL(2) * y);
}

// Slope g (per bin) of the log energy density along range inside a pixel's footprint of `width` bins,
// from the densities of its row neighbours: rho = e / w (energy over footprint width, bins), their centres
// `span` bins apart (up minus down). The density of a surface's echo changes fast along range where the
// rows are sparse (a grazing seabed: r^-5 from spreading and incidence, plus the rows' own spacing), and
// a flat box over a footprint of metres leaves a saw-tooth of +-0.5 dB across the bins. 0 (a flat box)
// where a neighbour is missing or empty; |g| is capped at 1 per bin and at 8 over the footprint, so the
// density never spans more than e^8 across a pixel. The ratio's two products must not underflow to 0
// either: tiny echoes (absorption of 10 dB/m over 16 m) made 0 / 0, a NaN that the cap kept, in float on
// the CPU (a device that flushes denormals to 0 saw no slope there).
VKS_FN bool footprint_slope_known(REAL e_up, REAL w_up, REAL e_down, REAL w_down, REAL span) {
    return e_up > REAL(0) && e_down > REAL(0) && w_up > REAL(0) && w_down > REAL(0) && abs(span) > REAL(0) &&
           e_up * w_down > REAL(0) && e_down * w_up > REAL(0);
}
VKS_FN REAL footprint_log_slope(REAL e_up, REAL w_up, REAL e_down, REAL w_down, REAL span, REAL width) {
    if (!footprint_slope_known(e_up, w_up, e_down, w_down, span)) {
        return REAL(0);
    }
    REAL g = log((e_up * w_down) / (e_down * w_up)) / span;
    REAL cap = min(REAL(1), REAL(8) / width);
    return min(max(g, -cap), cap);
}

// Share of a pixel's footprint [lo, hi] (bin coordinates from the spread's origin, centre c = (lo + hi) /
// 2) that falls into bin k (counted from the same origin), with the energy density along range
// proportional to exp(g (x - c)); inv_norm = 1 / ((hi - lo) sinhc(g (hi - lo) / 2)) normalizes its
// integral over the footprint to 1. With g = 0 this is the box: (overlap length) / (hi - lo). The range window gates:
// what lies below bin 0 or above the last bin is not recorded, so the shares of the bins add up to the part of the
// footprint inside.
VKS_FN REAL footprint_share(REAL lo, REAL hi, REAL centre, REAL g, REAL inv_norm, int k) {
    REAL a = max(lo, REAL(k));
    REAL b = min(hi, REAL(k + 1));
    if (!(b > a)) {
        return REAL(0);
    }
    REAL half_len = REAL(0.5) * (b - a);
    return (b - a) * exp(g * (a + half_len - centre)) * sinhc_of(g * half_len) * inv_norm;
}

// Cosine of incidence of a unit normal n already turned to face the sonar, at a pixel of sonar-frame
// position P and slant range r: clamp(-dot(n, P) / r, 0, 1).
VKS_FN REAL incidence_cos(REAL n_dot_p, REAL range_m) {
    return min(max(-n_dot_p / range_m, REAL(0)), REAL(1));
}

#undef VKS_FN
