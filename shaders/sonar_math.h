// The sonar model's formulas, written once for GLSL and C++.
//
// No include guard on purpose: C++ includes this file twice, with REAL = float and REAL = double,
// inside namespaces vksonar::math_f32 / vksonar::math_f64 (see src/core/sonar_math.hpp). GLSL
// includes it once with REAL = float. Only scalar code that is valid in both languages goes here:
// REAL(x) casts, sqrt/sin/cos/exp/pow/abs/min/max, VKS_ATAN2 for the two-argument arctangent.
//
// Geometry conventions (docs/conventions.md): sonar frame x forward, y left (port), z up.
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
// and the two roundings move it by < 16 * 2^-23 (tests/stages/cpu_depth_test.cpp checks every column).
VKS_FN uint slice_of_column(uint c, REAL inv_slice_columns) {
    return uint((REAL(c) + REAL(0.5)) * inv_slice_columns);
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
VKS_FN REAL pattern_power(uint shape, REAL k, REAL half_width, REAL chebyshev_a, REAL a) {
    if (shape == 0u) { // box
        return abs(a) <= half_width ? REAL(1) : REAL(0);
    }
    if (shape == 3u) { // gaussian
        return exp(-k * a * a);
    }
    REAL x = k * sin(a);
    if (shape == 4u) { // chebyshev
        REAL d = chebyshev_a * chebyshev_a - x * x;
        REAL amp_cheb = d >= REAL(0) ? cosh(sqrt(d)) : cos(sqrt(-d));
        amp_cheb = amp_cheb / cosh(chebyshev_a);
        return amp_cheb * amp_cheb;
    }
    REAL amp = sinc_of(x);
    if (shape == 2u) { // hann-tapered aperture: sinc(x) / (1 - (x/pi)^2), removable singularity at x = pi
        REAL t = x / REAL(3.14159265358979323846);
        REAL den = REAL(1) - t * t;
        if (abs(den) < REAL(1e-4)) {
            amp = REAL(0.5);
        } else {
            amp = amp / den;
        }
    }
    return amp * amp;
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
    if (model == 0u) { // lambert
        return c;
    }
    if (model == 2u) { // rough: lambert + facet term
        return c + specular_ratio * specular_facet(c, inv_two_slope_sq);
    }
    return REAL(1); // constant
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

// Range extent (m) of a pixel from the slant ranges of its row neighbours (0 = no hit): half the
// spread between the neighbours on the same surface (|r_q - r| <= jump_rel r), the one-sided step at
// an edge, 0 for an isolated pixel. Used by the footprint range kernel.
VKS_FN REAL pixel_range_extent(REAL r_up, REAL r, REAL r_down, REAL jump_rel) {
    REAL jump = jump_rel * r;
    bool up = r_up > REAL(0) && abs(r_up - r) <= jump;
    bool down = r_down > REAL(0) && abs(r_down - r) <= jump;
    if (up && down) {
        return REAL(0.5) * abs(r_down - r_up);
    }
    if (up) {
        return abs(r_up - r);
    }
    if (down) {
        return abs(r_down - r);
    }
    return REAL(0);
}

// Share of a box [lo, hi] (bin coordinates, 1 / (hi - lo) = inv_width) that falls into bin k of
// `bins`; bin 0 also takes everything below the grid and the last bin everything above, so the
// shares of bins 0..bins-1 always sum to 1 (energy is kept).
VKS_FN REAL footprint_share(REAL lo, REAL hi, REAL inv_width, int k, int bins) {
    REAL cell_lo = k == 0 ? lo : REAL(k);
    REAL cell_hi = k == bins - 1 ? hi : REAL(k + 1);
    return max(min(hi, cell_hi) - max(lo, cell_lo), REAL(0)) * inv_width;
}

// Cosine of incidence of a unit normal n already turned to face the sonar, at a pixel of sonar-frame
// position P and slant range r: clamp(-dot(n, P) / r, 0, 1).
VKS_FN REAL incidence_cos(REAL n_dot_p, REAL range_m) {
    return min(max(-n_dot_p / range_m, REAL(0)), REAL(1));
}

// Face normal of the depth pass's attachment (normal_method = geometric) in the sonar frame. The
// attachment holds the plane normal q in clip-linear coordinates (x_clip, y_clip, w_clip) =
// diag(1 / tan_half_h, 1 / tan_half_v, 1) * camera, so the camera-frame normal is (inverse transpose)
// (q.x / tan_half_h, q.y / tan_half_v, q.z); camera (right, down, forward) of the slice at azimuth
// (cos, sin) to sonar: right = (sin, -cos, 0), down = (0, 0, -1), forward = (cos, sin, 0).
VKS_FN REAL face_normal_sonar_x(REAL qx, REAL qz, REAL tan_half_h, REAL cs, REAL sn) {
    return (qx / tan_half_h) * sn + qz * cs;
}
VKS_FN REAL face_normal_sonar_y(REAL qx, REAL qz, REAL tan_half_h, REAL cs, REAL sn) {
    return qz * sn - (qx / tan_half_h) * cs;
}
VKS_FN REAL face_normal_sonar_z(REAL qy, REAL tan_half_v) {
    return -(qy / tan_half_v);
}

#undef VKS_FN
