// CPU reference of the depth pass (docs/pipeline.md §1): a scan-converting rasterizer with Vulkan's
// rules. Per slice s and draw i (slice-major DepthPush table), every triangle is transformed to clip
// space in double, clipped against 0 <= z <= w (Sutherland-Hodgman, then fan-triangulated), divided,
// mapped by the slice's viewport and rasterized inside the slice's scissor rectangle at pixel centres
// with the top-left fill rule (both windings, no culling). z_ndc is interpolated linearly in screen
// space; the depth test is strict GREATER in draw order against a buffer cleared to 0 (reversed-Z).
//
// Robustness: edge functions are evaluated in double, always from the same (lexicographically
// smaller) endpoint of an edge, so two triangles that share an edge compute exactly opposite values
// on it: no pixel is lost or covered twice along a shared edge, whatever the winding. Clipped vertices
// are interpolated from the inside endpoint, so a shared edge crossing a clip plane is cut at the same
// point in both triangles. Zero-area, non-finite and w <= 0 triangles produce nothing.
//
// With a face_normal buffer (normal_method = geometric), each pixel also records the plane normal of
// the triangle that won its depth test (docs/pipeline.md §1).
#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <utility>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "stages/cpu_simd.h"
#include "stages/cpu_stages.h"

namespace vksonar::cpu {
namespace {

struct ClipVertex {
    double x, y, z, w;
};

struct ScreenVertex {
    double x, y, z; // framebuffer x, y (pixels) and z_ndc (= framebuffer depth with range [0, 1])
};

// Outcode bits of the clip volume; a triangle whose three vertices share a bit is invisible.
enum : unsigned { kOutLeft = 1u, kOutRight = 2u, kOutTop = 4u, kOutBottom = 8u, kOutNear = 16u, kOutFar = 32u };

unsigned outcode(const ClipVertex& v) {
    unsigned code = 0;
    if (v.x < -v.w) code |= kOutLeft;
    if (v.x > v.w) code |= kOutRight;
    if (v.y < -v.w) code |= kOutTop;
    if (v.y > v.w) code |= kOutBottom;
    if (v.z > v.w) code |= kOutNear; // reversed-Z: z_ndc = 1 at the near plane
    if (v.z < 0.0) code |= kOutFar;
    return code;
}

// Clips a convex polygon against one plane: plane 0 keeps z >= 0, plane 1 keeps w - z >= 0.
// Returns the new vertex count (at most n + 1).
int clip_against(const ClipVertex* in, int n, ClipVertex* out, int plane) {
    auto dist = [plane](const ClipVertex& v) { return plane == 0 ? v.z : v.w - v.z; };
    int m = 0;
    for (int i = 0; i < n; ++i) {
        const ClipVertex& a = in[i];
        const ClipVertex& b = in[(i + 1) % n];
        const double da = dist(a), db = dist(b);
        const bool a_in = da >= 0.0, b_in = db >= 0.0;
        if (a_in) out[m++] = a;
        if (a_in != b_in) {
            // Interpolate from the inside endpoint: both triangles sharing this edge get the same point.
            const ClipVertex& p = a_in ? a : b;
            const ClipVertex& q = a_in ? b : a;
            const double dp = a_in ? da : db, dq = a_in ? db : da;
            const double t = dp / (dp - dq);
            ClipVertex r{p.x + t * (q.x - p.x), p.y + t * (q.y - p.y), p.z + t * (q.z - p.z), p.w + t * (q.w - p.w)};
            if (plane == 0) {
                r.z = 0.0; // exactly on the plane
            } else {
                r.z = r.w;
            }
            out[m++] = r;
        }
    }
    return m;
}

// Oriented edge from `from` to `to`, evaluated from its lexicographically smaller endpoint so that the
// reversed edge (in the neighbouring triangle) gives exactly the negated value.
struct Edge {
    double ax, ay, dx, dy; // canonical start point and direction
    double sign;           // +1: oriented edge runs a -> b; -1: reversed
    bool top_left;         // include samples exactly on the edge
    double dx_per_dy;      // dx / dy (0 for a horizontal edge): row_span's crossings without a division per row

    double eval(double px, double py) const { return sign * (dx * (py - ay) - dy * (px - ax)); }
    bool covers(double e) const { return e > 0.0 || (e == 0.0 && top_left); }
};

Edge make_edge(const ScreenVertex& from, const ScreenVertex& to) {
    const bool swap = to.x < from.x || (to.x == from.x && to.y < from.y);
    const ScreenVertex& a = swap ? to : from;
    const ScreenVertex& b = swap ? from : to;
    Edge e{a.x, a.y, b.x - a.x, b.y - a.y, swap ? -1.0 : 1.0, false, 0.0};
    if (e.dy != 0.0) e.dx_per_dy = e.dx / e.dy;
    // Interior on the positive side, framebuffer y down. A top edge is horizontal with the interior
    // below it (larger y): direction +x. A left edge has the interior to its right: direction -y.
    const double odx = to.x - from.x, ody = to.y - from.y;
    e.top_left = ody < 0.0 || (ody == 0.0 && odx > 0.0);
    return e;
}

struct Target {
    float* depth;
    std::uint32_t* material;
    std::uint32_t columns;
    std::int64_t x_begin, x_end;     // scissor columns [x_begin, x_end)
    std::int64_t row_begin, row_end; // the band of rows this pass writes (depth_pass)
    std::uint32_t material_id;
    bool simd = true;              // DepthRegion::simd
    bool vertex_cache = true;      // DepthRegion::vertex_cache
    float* face_normal = nullptr;  // rows * columns * 4 or null (normal_method = geometric)
    float triangle_normal[3] = {}; // the current triangle's unit plane normal, clip-linear coordinates
    // The band's edges in y_ndc, and whether it is less than the whole image (then triangles and
    // clusters wholly above or below it are skipped before their setup).
    double band_top_ndc = -1.0, band_bottom_ndc = 1.0;
    bool band = false;
    PixelBox* drawn = nullptr; // DepthRegion::drawn
};

// First pixel index whose centre is >= lo, clamped into [begin, end]; lo may be huge or -huge.
// ceil(x) > k exactly when x > k for an integer k, so the clamps test x itself, and inside them x is
// small enough to truncate: ceil without a call to libm (a baseline x86-64 build has no round
// instruction, and every triangle takes this twice).
[[gnu::always_inline]] inline std::int64_t first_pixel(double lo, std::int64_t begin, std::int64_t end) {
    const double x = lo - 0.5;
    if (!(x > static_cast<double>(begin))) return begin; // also NaN
    if (x > static_cast<double>(end)) return end;
    const auto t = static_cast<std::int64_t>(x); // toward zero
    return static_cast<double>(t) < x ? t + 1 : t;
}

// One past the last pixel index whose centre is <= hi, clamped into [begin, end]: floor(y) + 1 with
// y = hi - 0.5, and floor(y) + 1 < k exactly when y < k - 1 for an integer k.
[[gnu::always_inline]] inline std::int64_t last_pixel_end(double hi, std::int64_t begin, std::int64_t end) {
    const double y = hi - 0.5;
    if (!(y < static_cast<double>(end - 1))) return end; // also NaN
    if (y < static_cast<double>(begin - 1)) return begin;
    const auto t = static_cast<std::int64_t>(y); // toward zero
    return (static_cast<double>(t) > y ? t - 1 : t) + 1;
}

// Narrows [x0, x1) to the pixels of row centre cy that could be on e's covered side: where the edge
// crosses the row, solved for x and widened by a pixel each way, so the exact test in the loop still
// decides every pixel (the same bytes as testing the whole box) and a thin or slanted triangle no
// longer tests its box's empty corners. Horizontal edges leave it, and so do huge ones (below).
[[gnu::always_inline]] inline void row_span(const Edge& e, double cy, std::int64_t& x0, std::int64_t& x1) {
    if (e.dy == 0.0) return;
    const double run = (cy - e.ay) * e.dx_per_dy;
    // Below 2^40 in magnitude the crossing's rounding error (a few ulps: the slope is rounded once,
    // then the product) is under 2^-10 pixel, far inside the widening; beyond (a vertex near w = 0, a
    // nearly horizontal edge) the row keeps its box.
    if (!(std::abs(run) < 0x1p40 && std::abs(e.ax) < 0x1p40)) return;
    const double cross = e.ax + run;
    // e(cx) = sign (dx (cy - ay) - dy (cx - ax)) grows with cx where -sign dy > 0: covered to the right.
    if (-e.sign * e.dy > 0.0) {
        x0 = std::max(x0, first_pixel(cross - 1.0, x0, x1));
    } else {
        x1 = std::min(x1, last_pixel_end(cross + 1.0, x0, x1));
    }
}

// The depth test and write of pixel p at interpolated depth z (clamped already): strict GREATER,
// reversed-Z.
[[gnu::always_inline]] inline void depth_write(const Target& t, std::size_t p, double z) {
    const float d = static_cast<float>(z);
    if (d > t.depth[p]) {
        t.depth[p] = d;
        t.material[p] = t.material_id;
        if (t.face_normal) {
            float* n = t.face_normal + 4 * p;
            n[0] = t.triangle_normal[0];
            n[1] = t.triangle_normal[1];
            n[2] = t.triangle_normal[2];
            n[3] = 0.0f;
        }
    }
}

#if defined(__x86_64__) && defined(__GNUC__)
// The pixels [x0, x1) of row centre cy, four at a time as AVX lanes of doubles: each lane the same
// operations in the same order as the scalar loop of raster_triangle (the edge functions as Edge::eval,
// Edge::covers, the sum and the interpolated z, std::max / std::min's choices), so the same bytes. No
// FMA in this target: nothing is fused.
__attribute__((target("avx2"), always_inline)) inline void raster_row4(const Edge (&e)[3], const double (&vz)[3],
                                                                       double cy, std::int64_t x0, std::int64_t x1,
                                                                       std::size_t row_base, const Target& t) {
    const __m256d zero = _mm256_setzero_pd(), one = _mm256_set1_pd(1.0), half = _mm256_set1_pd(0.5);
    const __m256d lane = _mm256_setr_pd(0.0, 1.0, 2.0, 3.0);
    __m256d row_term[3], sign[3], dy[3], ax[3], top_left[3];
    for (int k = 0; k < 3; ++k) {
        row_term[k] = _mm256_set1_pd(e[k].dx * (cy - e[k].ay)); // eval's dx (py - ay)
        sign[k] = _mm256_set1_pd(e[k].sign);
        dy[k] = _mm256_set1_pd(e[k].dy);
        ax[k] = _mm256_set1_pd(e[k].ax);
        top_left[k] = _mm256_castsi256_pd(_mm256_set1_epi64x(e[k].top_left ? -1 : 0));
    }
    const __m256d z0 = _mm256_set1_pd(vz[0]), z1 = _mm256_set1_pd(vz[1]), z2 = _mm256_set1_pd(vz[2]);
    const __m256d end = _mm256_set1_pd(static_cast<double>(x1));
    for (std::int64_t x = x0; x < x1; x += 4) {
        const __m256d px = _mm256_add_pd(_mm256_set1_pd(static_cast<double>(x)), lane); // exact integers
        const __m256d cx = _mm256_add_pd(px, half);
        __m256d w[3];
        __m256d inside = _mm256_cmp_pd(px, end, _CMP_LT_OQ);
        for (int k = 0; k < 3; ++k) {
            w[k] = _mm256_mul_pd(sign[k], _mm256_sub_pd(row_term[k], _mm256_mul_pd(dy[k], _mm256_sub_pd(cx, ax[k]))));
            const __m256d covered = _mm256_or_pd(_mm256_cmp_pd(w[k], zero, _CMP_GT_OQ),
                                                 _mm256_and_pd(_mm256_cmp_pd(w[k], zero, _CMP_EQ_OQ), top_left[k]));
            inside = _mm256_and_pd(inside, covered);
        }
        if (_mm256_movemask_pd(inside) == 0) continue;
        const __m256d sum = _mm256_add_pd(_mm256_add_pd(w[0], w[1]), w[2]);
        inside = _mm256_and_pd(inside, _mm256_cmp_pd(sum, zero, _CMP_GT_OQ));
        const int mask = _mm256_movemask_pd(inside);
        if (mask == 0) continue;
        const __m256d weighted =
            _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(w[0], z0), _mm256_mul_pd(w[1], z1)), _mm256_mul_pd(w[2], z2));
        // std::min(1.0, std::max(0.0, z)): max_pd(z, 0) is (z > 0 ? z : 0), min_pd(m, 1) is (m < 1 ? m : 1)
        const __m256d z = _mm256_min_pd(_mm256_max_pd(_mm256_div_pd(weighted, sum), zero), one);
        alignas(32) double zs[4];
        _mm256_store_pd(zs, z);
        for (int l = 0; l < 4; ++l)
            if (mask & (1 << l)) depth_write(t, row_base + static_cast<std::size_t>(x + l), zs[l]);
    }
}

// The rows [y0, y1) of a triangle's box [x0, x1), each through raster_row4; built for AVX2 as a whole,
// so that row_span's rounding (ceil, floor) is one instruction here, not a call.
__attribute__((target("avx2"))) void raster_rows4(const Edge (&e)[3], const double (&vz)[3], std::int64_t x0,
                                                  std::int64_t x1, std::int64_t y0, std::int64_t y1, const Target& t) {
    for (std::int64_t py = y0; py < y1; ++py) {
        const double cy = static_cast<double>(py) + 0.5;
        std::int64_t row_x0 = x0, row_x1 = x1;
        // a box two vectors wide or less tests every pixel sooner than row_span narrows it
        if (x1 - x0 > 8) {
            row_span(e[0], cy, row_x0, row_x1);
            row_span(e[1], cy, row_x0, row_x1);
            row_span(e[2], cy, row_x0, row_x1);
        }
        raster_row4(e, vz, cy, row_x0, row_x1, static_cast<std::size_t>(py) * t.columns, t);
    }
}

#endif

// A triangle's pixels in its pixel box [x0, x1) x [y0, y1) (not empty; raster_triangle's box, within the
// target).
void raster_triangle_in_box(ScreenVertex v0, ScreenVertex v1, ScreenVertex v2, std::int64_t x0, std::int64_t x1,
                            std::int64_t y0, std::int64_t y1, const Target& t) {
    // Orientation from the same canonical edge function the coverage test uses.
    double area = make_edge(v0, v1).eval(v2.x, v2.y);
    if (!(area != 0.0) || !std::isfinite(area)) return; // zero area, NaN or overflow
    if (area < 0.0) std::swap(v1, v2);
    const Edge e0 = make_edge(v1, v2); // weight of v0
    const Edge e1 = make_edge(v2, v0); // weight of v1
    const Edge e2 = make_edge(v0, v1); // weight of v2
    if (t.drawn != nullptr) {
        PixelBox& box = *t.drawn;
        if (box.x0 >= box.x1) box = {x0, x1, y0, y1};
        box = {std::min(box.x0, x0), std::max(box.x1, x1), std::min(box.y0, y0), std::max(box.y1, y1)};
    }

#if defined(__x86_64__) && defined(__GNUC__)
    if (t.simd && has_avx2()) {
        const Edge edges[3] = {e0, e1, e2};
        const double vertex_z[3] = {v0.z, v1.z, v2.z};
        raster_rows4(edges, vertex_z, x0, x1, y0, y1, t);
        return;
    }
#endif
    for (std::int64_t py = y0; py < y1; ++py) {
        const double cy = static_cast<double>(py) + 0.5;
        const std::size_t row_base = static_cast<std::size_t>(py) * t.columns;
        std::int64_t row_x0 = x0, row_x1 = x1;
        row_span(e0, cy, row_x0, row_x1);
        row_span(e1, cy, row_x0, row_x1);
        row_span(e2, cy, row_x0, row_x1);
        for (std::int64_t px = row_x0; px < row_x1; ++px) {
            const double cx = static_cast<double>(px) + 0.5;
            const double w0 = e0.eval(cx, cy);
            if (!e0.covers(w0)) continue;
            const double w1 = e1.eval(cx, cy);
            if (!e1.covers(w1)) continue;
            const double w2 = e2.eval(cx, cy);
            if (!e2.covers(w2)) continue;
            const double sum = w0 + w1 + w2;
            if (!(sum > 0.0)) continue;
            // Screen-space linear interpolation of z_ndc (no perspective correction, as Vulkan does
            // for gl_FragCoord.z); clamped to the depth range against rounding.
            const double z = (w0 * v0.z + w1 * v1.z + w2 * v2.z) / sum;
            depth_write(t, row_base + static_cast<std::size_t>(px), std::min(1.0, std::max(0.0, z)));
        }
    }
}

void raster_triangle(const ScreenVertex& v0, const ScreenVertex& v1, const ScreenVertex& v2, const Target& t) {
    // The pixel box first: most triangles of a big mesh seen from afar hold no pixel centre, and then
    // the edges' setup (four divisions) is skipped. The box does not depend on the winding.
    const double min_x = std::min({v0.x, v1.x, v2.x}), max_x = std::max({v0.x, v1.x, v2.x});
    const double min_y = std::min({v0.y, v1.y, v2.y}), max_y = std::max({v0.y, v1.y, v2.y});
    const std::int64_t x0 = first_pixel(min_x, t.x_begin, t.x_end);
    const std::int64_t x1 = last_pixel_end(max_x, t.x_begin, t.x_end);
    const std::int64_t y0 = first_pixel(min_y, t.row_begin, t.row_end);
    const std::int64_t y1 = last_pixel_end(max_y, t.row_begin, t.row_end);
    if (x0 >= x1 || y0 >= y1) return;
    raster_triangle_in_box(v0, v1, v2, x0, x1, y0, y1, t);
}

ClipVertex transform(const double m[16], const float* pos) {
    const double x = pos[0], y = pos[1], z = pos[2];
    return {m[0] * x + m[4] * y + m[8] * z + m[12], m[1] * x + m[5] * y + m[9] * z + m[13],
            m[2] * x + m[6] * y + m[10] * z + m[14], m[3] * x + m[7] * y + m[11] * z + m[15]};
}

// Unit normal of the triangle's plane in clip-linear coordinates q = (x_clip, y_clip, w_clip), the
// quantity the GPU's depth_geometric.frag writes: cross of two edges in double (clip space is linear in
// the local position, so the unclipped vertices span the plane of every clipped piece); 0 if degenerate.
void plane_normal(const ClipVertex* v, float out[3]) {
    const double ax = v[1].x - v[0].x, ay = v[1].y - v[0].y, aw = v[1].w - v[0].w;
    const double bx = v[2].x - v[0].x, by = v[2].y - v[0].y, bw = v[2].w - v[0].w;
    const double n[3] = {ay * bw - aw * by, aw * bx - ax * bw, ax * by - ay * bx};
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int k = 0; k < 3; ++k)
        out[k] = len > 0.0 && std::isfinite(len) ? static_cast<float>(n[k] / len) : 0.0f;
}

// Bits: 1 above the band (y_ndc < top), 2 below it (y_ndc > bottom), as half-spaces of clip space (so
// also for w <= 0), with a margin far below a pixel and far above float rounding (cull_depth_clusters).
unsigned band_outcode(double y, double w, double magnitude, const Target& t) {
    const double tol = 1e-5 * magnitude;
    unsigned code = 0;
    if (y < t.band_top_ndc * w - tol) code |= 1u;
    if (y > t.band_bottom_ndc * w + tol) code |= 2u;
    return code;
}

// Whether some corner of the cluster's bounding box is not wholly above or below the band (the same
// corners and margin as cull_depth_clusters).
bool cluster_reaches_band(const DepthCluster& cluster, const shared::DepthPush& push, const Target& t) {
    unsigned every = 3u;
    for (int corner = 0; corner < 8 && every; ++corner) {
        double clip[4], magnitude[4];
        cluster_corner_clip(cluster, push.clip_from_local, corner, clip, magnitude);
        every &= band_outcode(clip[1], clip[3], magnitude[1] + magnitude[3], t);
    }
    return every == 0u;
}

bool finite(const ClipVertex& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z) && std::isfinite(v.w);
}

// A clip-space vertex's place in the view: framebuffer x, y and z_ndc (w > 0 checked by the caller).
ScreenVertex project(const ClipVertex& c, double x_offset, double half_w, double half_h) {
    const double xn = c.x / c.w, yn = c.y / c.w, zn = c.z / c.w;
    return {x_offset + (xn + 1.0) * half_w, (yn + 1.0) * half_h, zn};
}

// Whether the triangle is wholly above or below the target's band of rows.
bool outside_band(const ClipVertex& a, const ClipVertex& b, const ClipVertex& c, const Target& t) {
    unsigned every = 3u;
    for (const ClipVertex* v : {&a, &b, &c})
        every &= band_outcode(v->y, v->w, std::abs(v->y) + std::abs(v->w), t);
    return every != 0u;
}

// Clips the triangle poly[0..2] against the near and far planes where it crosses them, projects the
// pieces and rasterizes them as a fan.
void clip_and_raster(ClipVertex (&poly)[8], unsigned codes_or, double x_offset, double half_w, double half_h,
                     const Target& target) {
    ClipVertex tmp[8];
    int n = 3;
    if (codes_or & (kOutNear | kOutFar)) {
        n = clip_against(poly, n, tmp, 0);
        if (n < 3) return;
        n = clip_against(tmp, n, poly, 1);
        if (n < 3) return;
    }
    ScreenVertex sv[8];
    for (int k = 0; k < n; ++k) {
        if (!(poly[k].w > 0.0)) return;
        sv[k] = project(poly[k], x_offset, half_w, half_h);
    }
    for (int k = 1; k + 1 < n; ++k)
        raster_triangle(sv[0], sv[k], sv[k + 1], target);
}

// first_pixel and last_pixel_end of a vertex's x or y in [lo, hi] (a target's columns or rows, far
// below 2^31), without branches: a vertex position here is finite or +-inf (a finite clip vertex with
// w > 0), never NaN, so clamping first gives the same integer (x <= lo: lo; x > hi: hi; else ceil x,
// and floor likewise), and the clamped value truncates exactly. Where vertices straddle a pixel edge
// at random, first_pixel's branches were mispredicted half the time.
[[gnu::always_inline]] inline std::int32_t first_pixel_of_vertex(double at, double lo, double hi) {
    double x = at - 0.5;
    x = x > lo ? x : lo;
    x = x > hi ? hi : x;
    const auto t = static_cast<std::int32_t>(x); // x >= lo >= 0: toward zero is floor
    return t + static_cast<std::int32_t>(static_cast<double>(t) < x);
}
[[gnu::always_inline]] inline std::int32_t last_pixel_end_of_vertex(double at, double lo, double hi) {
    double y = at - 0.5;
    y = y < lo - 1.0 ? lo - 1.0 : y;
    y = y < hi - 1.0 ? y : hi - 1.0;
    const auto t = static_cast<std::int32_t>(y); // toward zero: y >= -1
    return t - static_cast<std::int32_t>(static_cast<double>(t) > y) + 1;
}

// The per-vertex work of one run (transform, outcode, projection) done once per vertex, not once per
// corner of every triangle: a run of a grid's 512 triangles indexes 289 vertices, each a corner of up
// to six triangles. Same values as the per-corner path (same functions, same inputs): same bytes.
struct RunVertices {
    static constexpr std::uint32_t kCapacity = 640; // 48 KiB of stack; a wider run takes the per-corner path
    static constexpr unsigned kNotFinite = 0x100u;  // above the outcode bits
    ClipVertex clip[kCapacity];
    ScreenVertex screen[kCapacity]; // valid where clip.w > 0
    unsigned code[kCapacity];       // outcode, or kNotFinite
    // Where clip.w > 0: first_pixel and last_pixel_end of the vertex's own x and y in the target. Both
    // are monotone, so a triangle's pixel box is the least and greatest of its vertices' (raster_triangle's
    // box exactly): a triangle holding no pixel centre, most of a big mesh seen from afar, is dropped here
    // with integer compares, and the others hand their box to raster_triangle_in_box.
    std::int32_t x_first[kCapacity], x_end[kCapacity], y_first[kCapacity], y_end[kCapacity];
};

void rasterize_run_cached(const SceneData& scene, const double (&m)[16], std::uint32_t first_vertex,
                          const std::uint32_t* idx, std::uint32_t index_count, std::uint32_t lowest,
                          std::uint32_t vertex_count, double x_offset, double half_w, double half_h, Target& target) {
    RunVertices cache; // not value-initialised: entries [0, vertex_count) are written before they are read
    const double x_lo = static_cast<double>(target.x_begin), x_hi = static_cast<double>(target.x_end);
    const double y_lo = static_cast<double>(target.row_begin), y_hi = static_cast<double>(target.row_end);
    const float* positions = scene.positions.data() + 3 * (std::size_t(first_vertex) + lowest);
    for (std::uint32_t v = 0; v < vertex_count; ++v) {
        const ClipVertex c = transform(m, positions + 3 * std::size_t(v));
        cache.clip[v] = c;
        cache.code[v] = finite(c) ? outcode(c) : RunVertices::kNotFinite;
        if (c.w > 0.0) {
            const ScreenVertex sv = project(c, x_offset, half_w, half_h);
            cache.screen[v] = sv;
            cache.x_first[v] = first_pixel_of_vertex(sv.x, x_lo, x_hi);
            cache.x_end[v] = last_pixel_end_of_vertex(sv.x, x_lo, x_hi);
            cache.y_first[v] = first_pixel_of_vertex(sv.y, y_lo, y_hi);
            cache.y_end[v] = last_pixel_end_of_vertex(sv.y, y_lo, y_hi);
        }
    }
    for (std::uint32_t tri = 0; tri + 3 <= index_count; tri += 3) {
        const std::uint32_t a = idx[tri] - lowest, b = idx[tri + 1] - lowest, c = idx[tri + 2] - lowest;
        assert(a < vertex_count && b < vertex_count && c < vertex_count); // the run's index range
        const unsigned c0 = cache.code[a], c1 = cache.code[b], c2 = cache.code[c];
        if ((c0 | c1 | c2) & RunVertices::kNotFinite) continue;
        if (c0 & c1 & c2) continue; // entirely outside one plane of the clip volume
        if (target.band && outside_band(cache.clip[a], cache.clip[b], cache.clip[c], target)) continue;
        if (target.face_normal || ((c0 | c1 | c2) & (kOutNear | kOutFar))) {
            ClipVertex poly[8]; // not value-initialised: clip_against writes what it reads past the first three
            poly[0] = cache.clip[a];
            poly[1] = cache.clip[b];
            poly[2] = cache.clip[c];
            if (target.face_normal) plane_normal(poly, target.triangle_normal);
            if ((c0 | c1 | c2) & (kOutNear | kOutFar)) {
                clip_and_raster(poly, c0 | c1 | c2, x_offset, half_w, half_h, target);
                continue;
            }
        }
        if (!(cache.clip[a].w > 0.0 && cache.clip[b].w > 0.0 && cache.clip[c].w > 0.0)) continue;
        const std::int32_t x0 = std::min({cache.x_first[a], cache.x_first[b], cache.x_first[c]});
        const std::int32_t x1 = std::max({cache.x_end[a], cache.x_end[b], cache.x_end[c]});
        const std::int32_t y0 = std::min({cache.y_first[a], cache.y_first[b], cache.y_first[c]});
        const std::int32_t y1 = std::max({cache.y_end[a], cache.y_end[b], cache.y_end[c]});
        if (x0 >= x1 || y0 >= y1) continue;
        raster_triangle_in_box(cache.screen[a], cache.screen[b], cache.screen[c], x0, x1, y0, y1, target);
    }
}

// The least and the greatest of idx[0 .. count), count > 0.
std::pair<std::uint32_t, std::uint32_t> index_range(const std::uint32_t* idx, std::uint32_t count) {
    std::uint32_t lowest = idx[0], highest = idx[0];
    for (std::uint32_t k = 1; k < count; ++k) {
        lowest = std::min(lowest, idx[k]);
        highest = std::max(highest, idx[k]);
    }
    return {lowest, highest};
}

// One run of triangles of one draw (a whole mesh, or one cluster of it) into one slice; its indices lie
// in [lowest, highest].
void rasterize_run(const SceneData& scene, const shared::DepthPush& push, std::uint32_t first_vertex,
                   const std::uint32_t* idx, std::uint32_t index_count, std::uint32_t lowest, std::uint32_t highest,
                   double x_offset, double half_w, double half_h, Target& target) {
    target.material_id = push.material_id;
    double m[16];
    for (int k = 0; k < 16; ++k)
        m[k] = push.clip_from_local[k];
    const std::size_t vertex_limit = scene.positions.size() / 3;
    index_count -= index_count % 3;
    if (index_count == 0) return;
    if (target.vertex_cache && highest - lowest < RunVertices::kCapacity &&
        std::size_t(first_vertex) + highest < vertex_limit) {
        rasterize_run_cached(scene, m, first_vertex, idx, index_count, lowest, highest - lowest + 1, x_offset, half_w,
                             half_h, target);
        return;
    }
    for (std::uint32_t tri = 0; tri < index_count; tri += 3) {
        ClipVertex poly[8];
        bool ok = true;
        for (int k = 0; k < 3 && ok; ++k) {
            const std::size_t v = static_cast<std::size_t>(first_vertex) + idx[tri + k];
            if (v >= vertex_limit) {
                ok = false;
                break;
            }
            poly[k] = transform(m, scene.positions.data() + 3 * v);
            ok = finite(poly[k]);
        }
        if (!ok) continue;
        const unsigned c0 = outcode(poly[0]), c1 = outcode(poly[1]), c2 = outcode(poly[2]);
        if (c0 & c1 & c2) continue; // entirely outside one plane of the clip volume
        if (target.band && outside_band(poly[0], poly[1], poly[2], target)) continue;
        if (target.face_normal) plane_normal(poly, target.triangle_normal);
        clip_and_raster(poly, c0 | c1 | c2, x_offset, half_w, half_h, target);
    }
}

} // namespace

void depth_pass(const Plan& plan, const SceneData& scene, const std::vector<shared::DepthPush>& draws, float* depth,
                std::uint32_t* material, float* face_normal, const DepthClusters* clusters, const DepthRegion& region) {
    const std::uint32_t columns = plan.columns, rows = plan.rows;
    const std::uint32_t row_begin = region.row_begin, row_end = std::min(region.row_end, rows);
    const std::uint32_t view_begin = region.view_begin, view_end = std::min(region.view_end, plan.views);
    if (row_begin >= row_end || view_begin >= view_end) return;
    // the region's pixels: rows [row_begin, row_end) of the views' columns (the views are contiguous)
    const std::size_t column_first = view_first_column(plan, view_begin);
    const std::size_t column_end = view_first_column(plan, view_end - 1) + view_columns(plan, view_end - 1);
    for (std::size_t row = row_begin; row < row_end && region.clear; ++row) {
        const std::size_t first = row * columns + column_first, last = row * columns + column_end;
        std::fill(depth + first, depth + last, 0.0f);
        std::fill(material + first, material + last, shared::kNoMaterial);
        if (face_normal) std::fill(face_normal + 4 * first, face_normal + 4 * last, 0.0f);
    }

    const std::size_t draw_count = scene.draws.size();
    const double half_h = 0.5 * rows;
    for (std::uint32_t s = view_begin; s < view_end; ++s) {
        // the view's viewport: its columns [view_first_column, + view_columns)
        const std::int64_t view_first = view_first_column(plan, s), width = view_columns(plan, s);
        const double half_w = 0.5 * static_cast<double>(width);
        Target target{depth, material, columns, view_first, view_first + width, row_begin, row_end, 0};
        target.simd = region.simd && plan.config.cpu_vector_loops != CpuVectorLoops::off;
        target.vertex_cache = region.vertex_cache;
        target.face_normal = face_normal;
        target.band = row_begin > 0 || row_end < rows;
        target.band_top_ndc = 2.0 * row_begin / rows - 1.0;
        target.band_bottom_ndc = 2.0 * row_end / rows - 1.0;
        target.drawn = region.drawn;
        const double x_offset = static_cast<double>(view_first);
        if (clusters) {
            const std::size_t count = clusters->runs.size();
            for (std::size_t c = 0; c < count; ++c) {
                const DepthCluster& run = clusters->runs[c];
                const std::size_t slot = s * draw_count + run.draw;
                if (slot >= draws.size() || !clusters->drawn[s * count + c]) continue;
                if (target.band && !cluster_reaches_band(run, draws[slot], target)) continue;
                rasterize_run(scene, draws[slot], run.first_vertex, scene.indices.data() + run.first_index,
                              run.index_count, run.index_min, run.index_max, x_offset, half_w, half_h, target);
            }
            continue;
        }
        for (std::size_t i = 0; i < draw_count; ++i) {
            const std::size_t slot = s * draw_count + i;
            if (slot >= draws.size()) break;
            const SceneDraw& draw = scene.draws[i];
            if (draw.mesh >= scene.meshes.size()) continue;
            const MeshRange& mesh = scene.meshes[draw.mesh];
            if (static_cast<std::size_t>(mesh.first_index) + mesh.index_count > scene.indices.size()) continue;
            const std::uint32_t index_count = mesh.index_count - mesh.index_count % 3;
            if (index_count == 0) continue;
            const std::uint32_t* idx = scene.indices.data() + mesh.first_index;
            const auto [lowest, highest] = index_range(idx, index_count);
            rasterize_run(scene, draws[slot], mesh.first_vertex, idx, index_count, lowest, highest, x_offset, half_w,
                          half_h, target);
        }
    }
}

} // namespace vksonar::cpu
