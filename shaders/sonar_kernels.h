// The per-pixel kernels of the stages, written once for GLSL and C++: the shaders call them on the
// GPU, the CPU backend (src/stages/cpu_*.cpp) calls the same functions in its loops. What differs
// between the backends is only how a kernel's inputs are loaded and where its result is stored.
//
// Included after sonar_math.h, in the same way (no include guard; C++ includes it once per REAL inside
// math_f32 / math_f64, src/core/sonar_math.hpp). Vector types are GLSL's vec2/vec3/vec4; in C++ they
// are GLM's of the working precision (glm::vec3 or glm::dvec3), with the same operators and the
// functions dot, cross and length. Two macros cover what the languages spell differently:
//   VKS_OUT(T)   an out parameter (GLSL `out T`, C++ `T&`);
//   VKS_PRECISE  a value that must not be contracted into a fused multiply-add (GLSL `precise`; the C++
//                library is compiled with -ffp-contract=off, CMakeLists.txt), so both round alike.

#ifndef REAL
#error "define REAL (float or double) before including sonar_kernels.h"
#endif
#ifdef __cplusplus
#define VKS_FN inline
// A kernel called per pixel from more than one CPU loop, inlined into each (the compiler's own
// heuristic gave up on range_spread once the line array's profile loop called it too: +6 % beamform).
#define VKS_FN_INLINE inline __attribute__((always_inline))
#define VKS_OUT(T) T&
#define VKS_PRECISE
#else
#define VKS_FN
#define VKS_FN_INLINE
#define VKS_OUT(T) out T
#define VKS_PRECISE precise
#endif

// ---------------------------------------------------------------------------------------------
// Pixel positions (stages 2 and 3)

// One view of the depth pass (SliceInfo, sonar_shared.h) in the working precision: its camera basis in
// the sonar frame, its half extents, and the cell of directions it is the one to see.
struct PixelView {
    vec3 forward;
    vec3 right;
    vec3 down;
    REAL tan_half_h;
    REAL tan_half_v;
    REAL sin_elevation_min;
    REAL sin_elevation_max;
    bool wedge;
    vec2 wedge_start; // (cos, sin) of the wedge's starboard edge
    vec2 wedge_end;   // (cos, sin) of its port edge
};

// The view of a SliceInfo entry (the float path of both backends reads these floats).
VKS_FN PixelView view_of_slice(SliceInfo s) {
    PixelView view;
    view.forward = vec3(REAL(s.forward_x), REAL(s.forward_y), REAL(s.forward_z));
    view.right = vec3(REAL(s.right_x), REAL(s.right_y), REAL(s.right_z));
    view.down = vec3(REAL(s.down_x), REAL(s.down_y), REAL(s.down_z));
    view.tan_half_h = REAL(s.tan_half_h);
    view.tan_half_v = REAL(s.tan_half_v);
    view.sin_elevation_min = REAL(s.sin_elevation_min);
    view.sin_elevation_max = REAL(s.sin_elevation_max);
    view.wedge = s.wedge != 0u;
    view.wedge_start = vec2(REAL(s.wedge_start_x), REAL(s.wedge_start_y));
    view.wedge_end = vec2(REAL(s.wedge_end_x), REAL(s.wedge_end_y));
    return view;
}

// A slice of the main band as a view: a level camera at azimuth (cos, sin) = (cs, sn), its elevation
// band |sin e| <= gate_sin (2: none), no wedge. The same values view_of_slice reads from its SliceInfo
// entry (plan_grid.cpp fills both from the same floats): the shaders build it from two table reads instead of
// seventeen.
VKS_FN PixelView level_slice_view(REAL cs, REAL sn, REAL tan_half_h, REAL tan_half_v, REAL gate_sin) {
    PixelView view;
    view.forward = vec3(cs, sn, REAL(0));
    view.right = vec3(sn, -cs, REAL(0));
    view.down = vec3(REAL(0), REAL(0), REAL(-1));
    view.tan_half_h = tan_half_h;
    view.tan_half_v = tan_half_v;
    view.sin_elevation_min = -gate_sin;
    view.sin_elevation_max = gate_sin;
    view.wedge = false;
    view.wedge_start = vec2(REAL(1), REAL(0));
    view.wedge_end = vec2(REAL(1), REAL(0));
    return view;
}

// Sonar-frame direction of pixel (u, v) of a view, scaled so that its view-space z is 1:
// forward + u right + v down. The pixel's position is view_z * pixel_ray(...). For a slice (a level
// camera at azimuth phi: forward (cos, sin, 0), right (sin, -cos, 0), down (0, 0, -1)) the zero terms
// add exactly nothing.
VKS_FN vec3 pixel_ray(REAL u, REAL v, PixelView view) {
    return view.forward + u * view.right + v * view.down;
}

// The sine of the elevation of the ray through (u, v) of a view: its z over its length (the basis is
// orthonormal, so |ray| = |(u, v, 1)|). For a slice the zero terms add nothing: -v / |(u, v, 1)|, bit for bit.
VKS_FN REAL view_elevation_sin(REAL u, REAL v, PixelView view) {
    return (view.forward.z + u * view.right.z + v * view.down.z) / sqrt(REAL(1) + u * u + v * v);
}

// The cosine along the array axis (the sonar's y axis, port) of pixel (u, v)'s direction in a view
// (pixel_ray): sin(theta) = cos(elevation) sin(azimuth), without an angle; theta is the steering angle of
// the line array's cone the ray lies on (the cone columns, "Beam geometry" below; the element pattern).
VKS_FN REAL array_axis_cosine(REAL u, REAL v, PixelView view) {
    return pixel_ray(u, v, view).y / sqrt(REAL(1) + u * u + v * v);
}

// A line array's element pattern (docs/pipeline.md §3, "element factor"): an element element_width
// wavelengths wide along the array hears the direction of sine `axis_sin` along it with power
// sinc^2(pi element_width axis_sin) (element_k = pi element_width); 1 with element_k = 0.
VKS_FN REAL element_power(REAL element_k, REAL axis_sin) {
    if (element_k == REAL(0)) {
        return REAL(1);
    }
    REAL a = sinc_of(element_k * axis_sin);
    return a * a;
}

// Whether the ray through (u, v) lies in the view's azimuth wedge (a tier view: the wedges of a band
// split its azimuths, each direction in exactly one: the starboard edge in, the port edge out); always
// true for a slice, whose side planes hold its azimuths.
VKS_FN bool in_view_wedge(REAL u, REAL v, PixelView view) {
    if (!view.wedge) {
        return true;
    }
    vec3 ray = pixel_ray(u, v, view);
    return ray.y * view.wedge_start.x - ray.x * view.wedge_start.y >= REAL(0) &&
           ray.y * view.wedge_end.x - ray.x * view.wedge_end.y < REAL(0);
}

// A reconstructed pixel: sonar-frame position, slant range, and whether the depth pass hit anything
// there (false outside the image too).
struct Sample {
    vec3 pos;
    REAL range;
    bool valid;
};

VKS_FN Sample no_sample() {
    Sample s;
    s.pos = vec3(REAL(0), REAL(0), REAL(0));
    s.range = REAL(0);
    s.valid = false;
    return s;
}

// The pixel at view z along `ray` (pixel_ray).
VKS_FN Sample sample_at(REAL view_z, vec3 ray) {
    Sample s;
    s.pos = view_z * ray;
    s.range = length(s.pos);
    s.valid = true;
    return s;
}

// ---------------------------------------------------------------------------------------------
// Normals (stage 2): Sobel 3x3 / 5x5 on reconstructed positions, one-sided differences near depth
// edges, and a facing-the-sonar fallback. Output (n.x, n.y, n.z, cos incidence).

// Faces the sonar: never brighter than a surface seen head on.
VKS_FN vec4 facing_normal(Sample p) {
    return vec4(-p.pos / p.range, REAL(1));
}

// n normalized and turned to face the sonar, with its cosine of incidence; a degenerate n (zero, or
// not finite) gives the facing fallback.
VKS_FN vec4 oriented_normal(Sample p, vec3 n) {
    REAL len = length(n);
    if (!(len > REAL(0) && len < REAL(1e30))) {
        return facing_normal(p);
    }
    n = n / len;
    if (dot(n, p.pos) > REAL(0)) {
        n = -n;
    }
    return vec4(n, incidence_cos(dot(n, p.pos), p.range));
}

// q is on the same surface as a pixel of range range_p: hit, and its range within `jump` metres.
VKS_FN bool same_surface(Sample q, REAL range_p, REAL jump) {
    return q.valid && abs(q.range - range_p) <= jump;
}

// One-sided difference along an axis towards the valid neighbour of closer range (ties: the + side).
// False when neither neighbour is valid.
VKS_FN bool one_sided_tangent(Sample minus, Sample centre, Sample plus, VKS_OUT(vec3) t) {
    if (plus.valid && (!minus.valid || abs(plus.range - centre.range) <= abs(minus.range - centre.range))) {
        t = plus.pos - centre.pos;
        return true;
    }
    if (minus.valid) {
        t = centre.pos - minus.pos;
        return true;
    }
    t = vec3(REAL(0), REAL(0), REAL(0));
    return false;
}

// A window column: rows j-1, j, j+1 of one pixel column.
struct Column3 {
    Sample up;
    Sample mid;
    Sample down;
};

// Sobel 3x3 normal of the centre pixel c.mid (valid) from the columns left, centre and right of it,
// where all 8 neighbours are on its surface; else one-sided differences, else facing.
VKS_FN vec4 sobel3_normal(Column3 l, Column3 c, Column3 r, REAL edge_relative_jump) {
    Sample p = c.mid;
    REAL jump = edge_relative_jump * p.range;
    bool smooth_region = same_surface(l.up, p.range, jump) && same_surface(l.mid, p.range, jump) &&
                         same_surface(l.down, p.range, jump) && same_surface(c.up, p.range, jump) &&
                         same_surface(c.down, p.range, jump) && same_surface(r.up, p.range, jump) &&
                         same_surface(r.mid, p.range, jump) && same_surface(r.down, p.range, jump);
    vec3 tx;
    vec3 ty;
    if (smooth_region) {
        tx = (r.up.pos - l.up.pos) + REAL(2) * (r.mid.pos - l.mid.pos) + (r.down.pos - l.down.pos);
        ty = (l.down.pos - l.up.pos) + REAL(2) * (c.down.pos - c.up.pos) + (r.down.pos - r.up.pos);
    } else {
        bool has_x = one_sided_tangent(l.mid, p, r.mid, tx);
        bool has_y = one_sided_tangent(c.up, p, c.down, ty);
        if (!has_x || !has_y) {
            return facing_normal(p);
        }
    }
    return oriented_normal(p, cross(tx, ty));
}

// sobel5: a window column of rows j-2 .. j+2.
struct Column5 {
    Sample up2;
    Sample up;
    Sample mid;
    Sample down;
    Sample down2;
};

VKS_FN Column3 inner_column(Column5 k) {
    Column3 col;
    col.up = k.up;
    col.mid = k.mid;
    col.down = k.down;
    return col;
}

VKS_FN bool column_same_surface(Column5 k, REAL range_p, REAL jump) {
    return same_surface(k.up2, range_p, jump) && same_surface(k.up, range_p, jump) &&
           same_surface(k.mid, range_p, jump) && same_surface(k.down, range_p, jump) &&
           same_surface(k.down2, range_p, jump);
}

// Derivative (-1 -2 0 2 1) as differences of symmetric pairs: the large positions cancel before the
// weights multiply.
VKS_FN vec3 derivative5(Sample m2, Sample m1, Sample p1, Sample p2) {
    return REAL(2) * (p1.pos - m1.pos) + (p2.pos - m2.pos);
}

// Sobel 5x5 where all 24 neighbours are on the centre pixel's surface, else exactly sobel3_normal.
// Smoothing (1 4 6 4 1), summed from the -2 side (docs/pipeline.md §2).
VKS_FN vec4 sobel5_normal(Column5 l2, Column5 l1, Column5 c, Column5 r1, Column5 r2, REAL edge_relative_jump) {
    Sample p = c.mid;
    REAL jump = edge_relative_jump * p.range;
    bool smooth5 = column_same_surface(l2, p.range, jump) && column_same_surface(l1, p.range, jump) &&
                   same_surface(c.up2, p.range, jump) && same_surface(c.up, p.range, jump) &&
                   same_surface(c.down, p.range, jump) && same_surface(c.down2, p.range, jump) &&
                   column_same_surface(r1, p.range, jump) && column_same_surface(r2, p.range, jump);
    if (!smooth5) {
        return sobel3_normal(inner_column(l1), inner_column(c), inner_column(r1), edge_relative_jump);
    }
    vec3 tx = derivative5(l2.up2, l1.up2, r1.up2, r2.up2);
    tx = tx + REAL(4) * derivative5(l2.up, l1.up, r1.up, r2.up);
    tx = tx + REAL(6) * derivative5(l2.mid, l1.mid, r1.mid, r2.mid);
    tx = tx + REAL(4) * derivative5(l2.down, l1.down, r1.down, r2.down);
    tx = tx + derivative5(l2.down2, l1.down2, r1.down2, r2.down2);
    vec3 ty = derivative5(l2.up2, l2.up, l2.down, l2.down2);
    ty = ty + REAL(4) * derivative5(l1.up2, l1.up, l1.down, l1.down2);
    ty = ty + REAL(6) * derivative5(c.up2, c.up, c.down, c.down2);
    ty = ty + REAL(4) * derivative5(r1.up2, r1.up, r1.down, r1.down2);
    ty = ty + derivative5(r2.up2, r2.up, r2.down, r2.down2);
    return oriented_normal(p, cross(tx, ty));
}

// normal_method = geometric: the depth pass's face normal q (clip-linear coordinates, sonar_math.h)
// of a pixel of a view, mapped to the sonar frame and oriented: the camera-frame normal
// (q.x / tan_half_h, q.y / tan_half_v, q.z) in the view's basis (right, down, forward).
VKS_FN vec4 geometric_normal(Sample p, vec3 q, PixelView view) {
    REAL nr = q.x / view.tan_half_h;
    REAL nd = q.y / view.tan_half_v;
    vec3 n = vec3(nr * view.right.x + q.z * view.forward.x + nd * view.down.x,
                  q.z * view.forward.y + nr * view.right.y + nd * view.down.y,
                  nd * view.down.z + nr * view.right.z + q.z * view.forward.z);
    return oriented_normal(p, n);
}

// ---------------------------------------------------------------------------------------------
// Echo (stage 3): the combined sonar equation of one pixel.

// The echo stage's per-frame constants in the working precision (the GPU's float SonarParams; the
// CPU's float path reads the same floats, its double path the Plan's doubles).
struct EchoConstants {
    REAL tan_half_h;
    REAL tan_half_v;
    REAL pixel_du; // 2 tan_half_h / slice_columns
    REAL pixel_dv; // 2 tan_half_v / rows
    REAL depth_a;
    REAL depth_b;
    REAL gate_min_m; // the range gate (SonarParams)
    REAL gate_max_m;
    REAL alpha_db_per_m;
    REAL vpattern_k;
    REAL vpattern_halfwidth_rad;
    REAL vpattern_chebyshev_a;
    REAL element_k; // SonarParams::element_k: pi element_width (in wavelengths); 0: point elements
};

// Which of the echo equation's terms a pipeline carries (the effect bits and the scene's materials).
struct EchoTerms {
    bool incidence;       // kEffectIncidence: the scattering factor of the material at cos_incidence
    bool rough_materials; // a material of the scene has kScatterRough (else the facet term is compiled out)
    bool vertical_pattern;
    uint vertical_shape; // kPattern*
    bool spreading;
    bool absorption;
};

// The material a hit pixel reflects with: its id, or material 0 (the config's default backscatter)
// where the id is outside the table (a host depth image, or kNoMaterial under a hit).
VKS_FN uint material_index(uint material_id, uint material_count) {
    uint m = material_id & kMaterialIdMask; // the instance id above it, when labels are on
    return m < material_count ? m : 0u;
}

// The power of a ray at elevation sine sin_e: 0 outside the view's elevation band (the elevation gate
// of a slice, SonarParams::elevation_gate_sin; a tier's band beyond it), else `power`.
VKS_FN REAL elevation_gated(REAL power, REAL sin_e, PixelView view) {
    return sin_e >= view.sin_elevation_min && sin_e <= view.sin_elevation_max ? power : REAL(0);
}

// The vertical pattern's power over the pixel (u, v) of a view, 0 outside the view's cell (its
// elevation band, and a tier view's azimuth wedge); 1 with the effect off (the pixel grid is then the
// beam, as the legacy plugins have it). A function of the pixel's place in the grid alone, which the
// CPU backend reads from a table made once (cpu_echo.cpp). k.pixel_dv is the view's row height.
VKS_FN REAL pixel_vertical_pattern(EchoConstants k, EchoTerms terms, REAL u, REAL v, PixelView view) {
    REAL vertical = REAL(1);
    if (terms.vertical_pattern && terms.vertical_shape == kPatternBox) {
        // a slice's (box and gaussian patterns have no side lobes: no tier views)
        vertical = pattern_power(kPatternBox, k.vpattern_k, k.vpattern_halfwidth_rad, k.vpattern_chebyshev_a,
                                 pixel_elevation(u, v)); // zero beyond vfov / 2, inside the gate
    } else if (terms.vertical_pattern) {
        // The pattern averaged over the pixel's height, by two-point Gauss-Legendre in v (exact where the
        // pattern is quadratic across the pixel). The centre alone is wrong next to a null, where the
        // pattern grows as the square of the distance d from it: a row of height D holds d^2 + D^2 / 12
        // of it, the centre gives d^2 (-1.25 dB for the row at the null). The box keeps its sharp edge.
        // Each point is gated on its own: a row that straddles the gate keeps the half inside it, and the
        // tier view beyond the gate the other half.
        REAL half_gap = REAL(0.28867513459481287) * k.pixel_dv; // D / (2 sqrt 3)
        REAL upper_sin = view_elevation_sin(u, v - half_gap, view);
        REAL lower_sin = view_elevation_sin(u, v + half_gap, view);
        REAL upper;
        REAL lower;
        if (terms.vertical_shape == kPatternGaussian) {
            upper = pattern_power(kPatternGaussian, k.vpattern_k, k.vpattern_halfwidth_rad, k.vpattern_chebyshev_a,
                                  pixel_elevation(u, v - half_gap));
            lower = pattern_power(kPatternGaussian, k.vpattern_k, k.vpattern_halfwidth_rad, k.vpattern_chebyshev_a,
                                  pixel_elevation(u, v + half_gap));
        } else { // the aperture patterns, from the elevation's sine (no arctangent, no sine)
            upper = aperture_pattern_power(terms.vertical_shape, k.vpattern_k, k.vpattern_chebyshev_a, upper_sin);
            lower = aperture_pattern_power(terms.vertical_shape, k.vpattern_k, k.vpattern_chebyshev_a, lower_sin);
        }
        if (!in_view_wedge(u, v, view)) {
            return REAL(0);
        }
        return REAL(0.5) * (elevation_gated(upper, upper_sin, view) + elevation_gated(lower, lower_sin, view));
    }
    return vertical;
}

// The pixel's pattern power: the vertical pattern's (pixel_vertical_pattern), times a line array's
// element pattern at the pixel's centre (element_power; it changes by a few 1e-4 across a pixel).
VKS_FN REAL pixel_vertical_power(EchoConstants k, EchoTerms terms, REAL u, REAL v, PixelView view) {
    REAL vertical = pixel_vertical_pattern(k, terms, u, v, view);
    if (k.element_k != REAL(0)) {
        vertical = vertical * element_power(k.element_k, array_axis_cosine(u, v, view));
    }
    return vertical;
}

// The slant range of the pixel (u, v) at reversed-Z depth d > 0.
VKS_FN REAL depth_slant_range(EchoConstants k, REAL d, REAL u, REAL v) {
    return slant_range(view_z_from_depth(d, k.depth_a, k.depth_b), u, v);
}

// (energy relative to SL, r) of a hit at slant range r with material `mat`, given the pixel's solid
// angle omega (pixel_solid_angle) and vertical power (pixel_vertical_power); (0, r) outside the range
// gate and where the vertical power is 0. cos_incidence is read only with terms.incidence.
VKS_FN vec2 echo_at_range(EchoConstants k, EchoTerms terms, REAL r, MaterialGpu mat, REAL cos_incidence, REAL omega,
                          REAL vertical) {
    // Outside the range gate, or outside the pixel's view's cell (a tier view's corner beyond its wedge: no
    // vertical power): nothing, at no cost (the product below would be exactly 0).
    if (r < k.gate_min_m || r >= k.gate_max_m || !(vertical > REAL(0))) {
        return vec2(REAL(0), r);
    }
    REAL scatter = REAL(1);
    if (terms.incidence && terms.rough_materials) {
        scatter = scatter_factor(mat.model, cos_incidence, REAL(mat.specular_ratio), REAL(mat.inv_two_slope_sq));
    } else if (terms.incidence && mat.model == kScatterLambert) {
        scatter = cos_incidence;
    }
    REAL e = echo_energy(REAL(mat.backscatter_linear), scatter, omega, r, k.alpha_db_per_m, vertical, terms.spreading,
                         terms.absorption);
    return vec2(e, r);
}

// (energy relative to SL, slant range) of the pixel (u, v) at reversed-Z depth d > 0 with material
// `mat`; (0, r) outside the range gate. cos_incidence is read only with terms.incidence. k: the
// view's constants (its half extents and pixel size).
VKS_FN vec2 echo_of_pixel(EchoConstants k, EchoTerms terms, REAL d, REAL u, REAL v, PixelView view, MaterialGpu mat,
                          REAL cos_incidence) {
    REAL r = depth_slant_range(k, d, u, v);
    if (r < k.gate_min_m || r >= k.gate_max_m) {
        return vec2(REAL(0), r);
    }
    return echo_at_range(k, terms, r, mat, cos_incidence, pixel_solid_angle(u, v, k.pixel_du, k.pixel_dv),
                         pixel_vertical_power(k, terms, u, v, view));
}

// ---------------------------------------------------------------------------------------------
// Range kernel (stage 4a): how one pixel's echo spreads over the range bins of its column's profile.

// The bins [k_first, k_last] a pixel's echo goes to (inside the window: what lies outside is gated
// away; none when k_first > k_last) and what range_share needs to split it.
struct RangeSpread {
    uint kernel; // kRangeKernel*
    int k_first;
    int k_last;
    int tent_k0;  // tent: the lower of its two bins (may lie outside the window)
    REAL tent_w1; // tent: the share of bin tent_k0 + 1
    // footprint: [lo, hi] in bin coordinates from bin `origin` (the pixel's own bin), its centre, log-density
    // slope g, 1 / integral. Measured from bin 0, a far pixel's edges would round to 6e-5 of a bin (a float
    // near 500), and a narrow footprint's share of the bin its edge falls in would move by 1e-4 of itself
    // with a last-bit change of its width (the GPU's square root and division are a few ulps from the
    // CPU's): the H100 put the profiles 1.4e-4 apart. From its own bin they round to 1e-7 of a bin.
    int origin;
    REAL lo;
    REAL hi;
    REAL centre;
    REAL g;
    REAL inv_norm;
};

// The spread of pixel `er` = (energy, range) from the five-row window of its column (up2, up: the rows
// above; down, down2: below; range 0 = no hit or outside the image) and the ranges of its row neighbours
// left and right (r_left, r_right; 0 = no hit or outside the pixel's view). range_min_m, inv_bin_width_m,
// absorption_per_bin: SonarParams; jump_rel: edge_relative_jump.
VKS_FN_INLINE RangeSpread range_spread(uint kernel, vec2 up2, vec2 up, vec2 er, vec2 down, vec2 down2, REAL r_left,
                                       REAL r_right, REAL range_min_m, REAL inv_bin_width_m, REAL jump_rel, uint bins,
                                       REAL absorption_per_bin) {
    RangeSpread s;
    s.kernel = kernel;
    s.k_first = 0;
    s.k_last = -1;
    s.tent_k0 = 0;
    s.tent_w1 = REAL(0);
    s.origin = 0;
    s.lo = REAL(0);
    s.hi = REAL(0);
    s.centre = REAL(0);
    s.g = REAL(0);
    s.inv_norm = REAL(0);
    REAL r = er.y;
    VKS_PRECISE REAL x = range_bin_coord(r, range_min_m, inv_bin_width_m);
    if (isnan(x)) {
        return s;
    }
    int nb = int(bins);
    if (kernel == kRangeKernelFootprint) {
        REAL a = footprint_edge_offset(up.y, up2.y, r, down.y, jump_rel);
        REAL b = footprint_edge_offset(down.y, down2.y, r, up.y, jump_rel);
        REAL a2 = a != REAL(0) ? a : footprint_missing_edge(b, down.y, down2.y, r);
        REAL b2 = b != REAL(0) ? b : footprint_missing_edge(a, up.y, up2.y, r);
        // From here on bin coordinates count from the pixel's own bin: f = x - floor(x) is exact.
        REAL base = floor(x);
        s.origin = int(base);
        VKS_PRECISE REAL f = x - base;
        VKS_PRECISE REAL xl = f + footprint_lo(a2, b2) * inv_bin_width_m;
        VKS_PRECISE REAL xh = f + footprint_hi(a2, b2) * inv_bin_width_m;
        // Down the column [xl, xh], across it [cl, ch] (bins from r): their sum spans [xl + cl, xh + ch]; a
        // box of the same variance (of a footprint that is the two boxes convolved) is
        // sqrt(w_column^2 + w_across^2) wide, centred where theirs add.
        vec2 across = footprint_across(r_left, r, r_right, jump_rel);
        VKS_PRECISE REAL cl = across.x * inv_bin_width_m;
        VKS_PRECISE REAL ch = across.y * inv_bin_width_m;
        VKS_PRECISE REAL column_centre = REAL(0.5) * (xl + xh);
        VKS_PRECISE REAL centre = column_centre + REAL(0.5) * (cl + ch);
        VKS_PRECISE REAL w_down_column = xh - xl;
        VKS_PRECISE REAL w_across = ch - cl;
        VKS_PRECISE REAL extent = sqrt(w_down_column * w_down_column + w_across * w_across);
        REAL width = min(extent > REAL(0) ? max(extent, REAL(kMinFootprintBins)) : REAL(1), REAL(kMaxFootprintBins));
        VKS_PRECISE REAL lo = centre - REAL(0.5) * width;
        VKS_PRECISE REAL hi = centre + REAL(0.5) * width;
        // the density's slope from the neighbours' footprints (both on this surface)
        REAL g = REAL(0);
        bool known = false;
        bool up_side = a != REAL(0) && up2.y > REAL(0);
        bool down_side = b != REAL(0) && down2.y > REAL(0);
        if (up_side && down_side) {
            VKS_PRECISE REAL w_up = REAL(0.5) * abs(up2.y - r) * inv_bin_width_m;
            VKS_PRECISE REAL w_down = REAL(0.5) * abs(r - down2.y) * inv_bin_width_m;
            // between the neighbours' footprint centres, (r + 2 r_q + r_q2) / 4 on either side
            VKS_PRECISE REAL span = (REAL(2) * (up.y - down.y) + (up2.y - down2.y)) * (REAL(0.25) * inv_bin_width_m);
            known = footprint_slope_known(up.x, w_up, down.x, w_down, span);
            g = footprint_log_slope(up.x, w_up, down.x, w_down, span, width);
        } else if (up_side || down_side) {
            // One side only (the surface's, the view's or the depth pass's last rows): the slope between
            // the neighbour's footprint on that side and this pixel's own. A flat box there leaves a
            // ramp of up to 0.9 dB across the footprint of a grazing seabed's last row before range_max.
            vec2 q = up_side ? up : down;
            REAL r_q2 = up_side ? up2.y : down2.y;
            VKS_PRECISE REAL w_q = REAL(0.5) * abs(r_q2 - r) * inv_bin_width_m;
            VKS_PRECISE REAL span =
                ((r + REAL(2) * q.y + r_q2) * REAL(0.25) - r) * inv_bin_width_m - (column_centre - f);
            known = footprint_slope_known(q.x, w_q, er.x, xh - xl, span);
            g = footprint_log_slope(q.x, w_q, er.x, xh - xl, span, width);
        }
        // Without a slope from the neighbours the surface's own density is taken flat, and the whole
        // density falls as absorption does across the footprint: g = -b (b = absorption_per_bin; 0 with
        // the effect off, as before).
        if (!known) {
            g = -absorption_per_bin;
        }
        s.lo = lo;
        s.hi = hi;
        s.centre = centre;
        s.g = g;
        // The pixel's energy holds absorption at its own range f; its footprint's parts lie up to metres
        // nearer and farther (a grazing seabed: 0.9 dB a side at 900 kHz, 90 m), and the absorption it
        // averages over them is more than at f: by a factor up to 1.3 dB there, which the spread's total
        // carries (shares summing to that factor, not to 1). The density is e^(g (x - c)): g is the whole
        // density's slope (the neighbours hold absorption at their ranges), the surface's own is g + b,
        // and the pixel's energy is the surface's integral times absorption at f, so the density's
        // integral is e^(-b (c - f)) / (width sinhc((g + b) width / 2)) of it. With the effect off
        // (b = 0) this is 1 / (width sinhc(g width / 2)), as before, bit for bit.
        VKS_PRECISE REAL y = REAL(0.5) * (g + absorption_per_bin) * width;
        REAL tilt = exp(min(max(-absorption_per_bin * (centre - f), REAL(-60)), REAL(60)));
        s.inv_norm = tilt / (width * sinhc_of(y));
        s.k_first = max(s.origin + int(floor(lo)), 0);
        s.k_last = min(s.origin + int(floor(hi)), nb - 1);
    } else if (kernel == kRangeKernelTent) {
        // Far outside the window both shares are gated away anyway; the clamp keeps floor() in int range.
        VKS_PRECISE REAL t = min(max(x - REAL(0.5), REAL(-2)), REAL(bins) + REAL(1));
        REAL k0f = floor(t);
        s.tent_w1 = t - k0f;
        s.tent_k0 = int(k0f);
        s.k_first = max(s.tent_k0, 0);
        s.k_last = min(s.tent_k0 + 1, nb - 1);
    } else if (x >= REAL(0) && x < REAL(bins)) { // nearest
        s.k_first = int(floor(x));
        s.k_last = s.k_first;
    }
    return s;
}

// The share of the pixel's energy that bin k (in [k_first, k_last]) receives.
VKS_FN_INLINE REAL range_share(RangeSpread s, int k) {
    if (s.kernel == kRangeKernelFootprint) {
        return footprint_share(s.lo, s.hi, s.centre, s.g, s.inv_norm, k - s.origin);
    }
    if (s.kernel == kRangeKernelTent) {
        return k == s.tent_k0 ? REAL(1) - s.tent_w1 : s.tent_w1;
    }
    return REAL(1);
}

// ---------------------------------------------------------------------------------------------
// Beam geometry (stage 4a, line_array): which cone columns a pixel's energy enters.
//
// A horizontal line array along the sonar y axis hears a direction by its cosine along the axis: the
// beam steered to theta receives the cone sin(theta) = cos(elevation) sin(azimuth). The range profiles
// are then kept per cone column (uniform in theta) instead of per pixel column, and each pixel goes to
// the two cone columns nearest its own theta, so a column of pixels (one azimuth) bends towards
// broadside as its elevation grows (docs/pipeline.md, "Beam geometry").

// array_axis_cosine (above, with the element pattern) gives a pixel its theta.

// A pixel's coordinate on the cone columns from its axis cosine: column c is centred at c, the fan's
// port edge (theta = half_fov_rad) at -0.5. Increases with the pixel column along a row (towards
// starboard) while the pixel grid stays within +-90 degrees of azimuth.
VKS_FN REAL cone_coord(REAL axis_cosine, REAL half_fov_rad, REAL inv_cone_step) {
    return (half_fov_rad - asin(min(max(axis_cosine, REAL(-1)), REAL(1)))) * inv_cone_step - REAL(0.5);
}

// The share of a pixel at cone coordinate x that cone column c (of `count`) receives: the tent between
// the two nearest column centres, the edge columns keeping what lies between their centre and the fan's
// edge (as the edge beams do, plan_beams.cpp); 0 outside the fan. The shares of a pixel inside sum to 1.
VKS_FN REAL cone_share(REAL x, int c, int count) {
    if (!(x >= REAL(-0.5) && x < REAL(count) - REAL(0.5))) {
        return REAL(0);
    }
    REAL xc = min(max(x, REAL(0)), REAL(count - 1));
    return max(REAL(1) - abs(xc - REAL(c)), REAL(0));
}

// A tier view's pixel (vertical side lobes) is up to accuracy.tier_pixel_ratio times as wide as a cone
// column: the tent between its two nearest columns would leave the columns between neighbouring pixels
// empty (beams that get nothing with the horizontal pattern off, +-2 dB from beam to beam with it on, on
// a flat seabed heard through the side lobes). So a tier pixel covers the cone coordinates [lo, hi]
// halfway to its row neighbours in its view (one-sided at the view's edges; a point where it has none)...
VKS_FN REAL cone_extent_low(REAL previous, REAL x, REAL next, bool has_previous, bool has_next) {
    VKS_PRECISE REAL half_step = REAL(0.5) * (next - x);
    return has_previous ? REAL(0.5) * (previous + x) : (has_next ? x - half_step : x);
}
VKS_FN REAL cone_extent_high(REAL previous, REAL x, REAL next, bool has_previous, bool has_next) {
    VKS_PRECISE REAL half_step = REAL(0.5) * (x - previous);
    return has_next ? REAL(0.5) * (x + next) : (has_previous ? x + half_step : x);
}

// ... and its energy spreads evenly over them: cone column c, whose cell is [c - 0.5, c + 0.5] (the
// cells tile the fan from its edge at -0.5 to count - 0.5), receives the part of [lo, hi] in its cell,
// over [lo, hi] clipped to the fan. As with cone_share a pixel is in the fan by its centre: one inside
// gives all its energy (its shares sum to 1, to rounding), one outside none. A pixel of no width takes
// cone_share.
VKS_FN REAL cone_extent_share(REAL x, REAL lo, REAL hi, int c, int count) {
    REAL a = max(lo, REAL(-0.5));
    REAL b = min(hi, REAL(count) - REAL(0.5));
    if (!(b > a) || !(x >= REAL(-0.5) && x < REAL(count) - REAL(0.5))) {
        return cone_share(x, c, count);
    }
    VKS_PRECISE REAL overlap = min(b, REAL(c) + REAL(0.5)) - max(a, REAL(c) - REAL(0.5));
    VKS_PRECISE REAL width = b - a;
    return max(overlap, REAL(0)) / width;
}

// ---------------------------------------------------------------------------------------------
// Sub-pixel returns (stage 4a, docs/pipeline.md "Sub-pixel objects"): an object smaller (or thinner)
// than a pixel is not rasterized; the host lists its triangles' pieces with their echo (src/core/subpixel.cpp)
// and the profile step adds each piece that the depth image does not hide.

// The vertical pattern's power along one ray of elevation sine sin_e; 1 with the effect off. A piece of a
// sub-pixel object lies on one ray, not across a pixel's height: the pattern at that ray, where
// pixel_vertical_power averages it over a row. No gate here: the host lists a piece only in the view
// whose cell (elevation band, tier wedge) holds its ray, so each direction counts once as a pixel's does.
VKS_FN REAL ray_vertical_power(EchoConstants k, EchoTerms terms, REAL sin_e, REAL axis_sin) {
    REAL element = element_power(k.element_k, axis_sin); // a line array's element pattern, as a pixel's
    if (!terms.vertical_pattern) {
        return element;
    }
    REAL p;
    if (terms.vertical_shape == kPatternBox || terms.vertical_shape == kPatternGaussian) {
        p = pattern_power(terms.vertical_shape, k.vpattern_k, k.vpattern_halfwidth_rad, k.vpattern_chebyshev_a,
                          asin(min(max(sin_e, REAL(-1)), REAL(1))));
    } else {
        p = aperture_pattern_power(terms.vertical_shape, k.vpattern_k, k.vpattern_chebyshev_a, sin_e);
    }
    return p * element;
}

// The echo (relative to SL) of a flat piece of surface of `area` m^2 at slant range r whose normal
// makes cos_incidence with the ray to it: the pixel's equation (echo_at_range) with the piece's solid
// angle, area cos_incidence / r^2, for the pixel's. So mu f(theta) A cos(theta) / r^4 (times the
// vertical pattern and absorption); over a Lambert sphere's visible half 2 pi a^2 mu / (3 r^4).
// 0 outside the range gate.
VKS_FN REAL facet_echo(EchoConstants k, EchoTerms terms, MaterialGpu mat, REAL area, REAL cos_incidence, REAL r,
                       REAL vertical) {
    return echo_at_range(k, terms, r, mat, cos_incidence, area * cos_incidence / (r * r), vertical).x;
}

// Whether a sub-pixel return at view z `view_z` (in its pixel's view) is seen past the surface the
// depth pass drew in that pixel (reversed-Z depth d, 0 = nothing drawn; material_id its id image's value):
// hidden only where that surface is nearer by more than 1e-5 of the distance (the depth's float
// resolution is ~1e-7 of it; a return lying on the surface it sits on stays), and is not one drawn with
// the silent material (an object whose echo is its returns: its own front, subpixel.h).
VKS_FN bool subpixel_visible(REAL d, uint material_id, uint silent_material, REAL view_z, REAL depth_a, REAL depth_b) {
    if (!(d > REAL(0)) || (material_id & kMaterialIdMask) == silent_material) {
        return true;
    }
    return view_z_from_depth(d, depth_a, depth_b) >= view_z * (REAL(1) - REAL(1e-5));
}

// ---------------------------------------------------------------------------------------------
// Far side lobes (stage 4c, docs/pipeline.md "Side lobes"): the pattern beyond the side-lobe
// kernel's reach, carried on a coarse grid of cells (Plan::far_cells). A beam puts its energy into
// its two nearest cells and reads the convolved cells back with the same two shares.

// The share of cell c in beam j's pair, beam_cell = (first cell, second cell, share of the second, 0)
// (Plan::far_beam_cell[8 j ...]); 0 for any other cell.
VKS_FN REAL far_cell_share(vec4 beam_cell, uint c) {
    if (uint(beam_cell.x) == c) {
        return REAL(1) - beam_cell.z;
    }
    if (uint(beam_cell.y) == c) {
        return beam_cell.z;
    }
    return REAL(0);
}

// Beam j's weight into channel `channel` of cell c: its share, times 1 (channel 0) or its phase's
// cosine (1) or sine (2), beam_phase = (cos 2k u_j, sin 2k u_j, 0, 0) (Plan::far_beam_cell[8 j + 4 ...];
// the deposit passes a profile column's, Plan::far_column_cell).
VKS_FN REAL far_deposit_weight(vec4 beam_cell, vec4 beam_phase, uint c, uint channel) {
    REAL share = far_cell_share(beam_cell, c);
    if (channel == 1u) {
        return share * beam_phase.x;
    }
    if (channel == 2u) {
        return share * beam_phase.y;
    }
    return share;
}

// The far side lobes at beam j from its read-back channels l0, l1, l2 (each its two cells' shares
// times the convolved cells): sin^2 = (1 - cos 2k u_s cos 2k u_j - sin 2k u_s sin 2k u_j) / 2 (the 1/2
// is in the weights), so l0 - cos l1 - sin l2, never below 0 (rounding); one channel: l0.
VKS_FN REAL far_sidelobe_level(vec4 beam_phase, REAL l0, REAL l1, REAL l2) {
    // A small difference of larger terms where the two phases agree: a fused multiply-add here would
    // round differently from the CPU, and the cancellation magnifies it.
    VKS_PRECISE REAL level = l0 - beam_phase.x * l1 - beam_phase.y * l2;
    return max(level, REAL(0));
}

// A scan cell with the far side lobes: the near kernel's sum plus its beam's far level. The near weights
// are the pattern less what the grid gives the same column (Plan::near_column_weight), so with one channel
// some are negative (the grid's mean level at the pattern's nulls): the sum is the pattern's, at least 0
// but for rounding, which is cut here so that no scan cell is negative.
VKS_FN REAL far_scan_cell(REAL near_sum, REAL far_level) {
    return max(near_sum + far_level, REAL(0));
}

#undef VKS_FN
#undef VKS_FN_INLINE
#undef VKS_OUT
#undef VKS_PRECISE
