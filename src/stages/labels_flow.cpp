// LabelsStage::flow's cells (labels_flow.h): each labelled point of `from` moved to the pose of `to`, its
// polar coordinates in either frame and whether `to`'s depth image sees it. With AVX2 four labelled cells
// go side by side through the same operations as the plain loop, lane by lane (the angle's asin and the
// beam search per lane), so the flow is the same bytes either way.
#include "stages/labels_flow.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "core/angles.h"
#include "core/sonar_math.hpp"
#include "stages/cpu_simd.h"
#include "stages/pixel_spread.h"

namespace vksonar::cpu {

BeamBuckets::BeamBuckets(const std::vector<double>& t) {
    const std::size_t n = t.size();
    if (n < 2 || !(t[0] > t[n - 1])) return;
    const std::size_t count = 4 * n;
    low = t[n - 1];
    per_rad = double(count) / (t[0] - t[n - 1]);
    first.resize(count);
    // bucket b's upper edge: low + (b + 1) / per_rad (the last one: beyond every angle)
    std::size_t j = n; // {j : t[j] < edge} is a suffix [j, n) of the decreasing table, growing with the edge
    for (std::size_t b = 0; b < count; ++b) {
        const double edge = b + 1 == count ? std::numeric_limits<double>::infinity() : low + double(b + 1) / per_rad;
        while (j > 0 && t[j - 1] < edge)
            --j;
        first[b] = static_cast<std::uint32_t>(j); // the first j with t[j] < edge
    }
}

namespace {

using M = Math<double>;

// Whether steering angle a lies strictly between the first and last beams of the table t (strictly
// decreasing, port first) and inside the fan: beam_coordinate's general case, between two beam centres.
inline bool between_beams(const std::vector<double>& t, double half_fan, double a) {
    const std::size_t n = t.size();
    return n >= 2 && std::abs(a) <= half_fan && a < t[0] && a > t[n - 1];
}

// The fractional beam index of steering angle a on the beam table: linear between beam centres,
// extrapolated by the edge spacing up to the fan's edge; NaN outside it.
double beam_coordinate(const Plan& plan, double a, const BeamBuckets& buckets) {
    const std::vector<double>& t = plan.beam_angle_rad;
    const std::size_t n = t.size();
    const double half = 0.5 * plan.config.hfov_deg * kDegToRad;
    if (between_beams(t, half, a)) {
        // first j with t[j] < a (t decreasing): the point lies between beams j - 1 and j
        const std::size_t j = buckets.first_below(t, a);
        return double(j - 1) + (t[j - 1] - a) / (t[j - 1] - t[j]);
    }
    if (n == 0 || !(std::abs(a) <= half)) return std::numeric_limits<double>::quiet_NaN();
    if (n == 1) return 0.0;
    if (a >= t[0]) return (t[0] - a) / (t[0] - t[1]);
    return double(n - 1) + (t[n - 1] - a) / (t[n - 2] - t[n - 1]); // a <= t[n - 1]
}

// d_beam: the beam coordinate's change; on a full circle (Plan::circular) the short way round, in
// [-beams / 2, beams / 2), as a point that crosses the seam between the last beam and the first moves by a
// few beams, not by nearly all of them.
inline double beam_step(const Plan& plan, double beam_from, double beam_to) {
    const double d = beam_to - beam_from;
    if (!plan.circular) return d;
    const double n = static_cast<double>(plan.beams);
    return d - n * std::floor(d / n + 0.5);
}

// The ranges a labelled point can lie at: the window, and with the tent kernel half a bin beyond either
// end (the tent puts a pixel there into the end bin, its point at the pixel's range).
struct PointWindow {
    double min_m, max_m;
};
PointWindow point_window(const Plan& plan) {
    const double reach = plan.params.range_kernel == shared::kRangeKernelTent ? 0.5 * plan.bin_width_m : 0.0;
    return {plan.config.range_min_m - reach, plan.config.range_max_m + reach};
}

// The point p (sonar frame) as (bin, beam) coordinates: bin b covers [b, b + 1) (cell k's centre at
// k + 0.5); NaN outside point_window. Returns p's range.
double polar_coordinates(const Plan& plan, const double p[3], double& bin, double& beam, const BeamBuckets& buckets) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double r = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    const PointWindow window = point_window(plan);
    bin = r >= window.min_m && r < window.max_m ? (r - plan.config.range_min_m) / plan.bin_width_m : nan;
    // The beam a direction is heard on: its cone (line array, the sine along the y axis) or its azimuth.
    const double angle = plan.line_array ? std::asin(std::clamp(p[1] / r, -1.0, 1.0)) : std::atan2(p[1], p[0]);
    beam = r > 0.0 ? beam_coordinate(plan, angle, buckets) : nan;
    return r;
}

// visible_in's test in view s, at the point's place (cx, cy) in the view's pixel grid: some pixel of the
// 3 x 3 around it holds a surface at least as far as r - tolerance. False outside the grid. With the
// footprint kernel a labelled point lies anywhere in its pixel's range footprint (labels.md), up to half
// of it beyond the pixel's own range: where no pixel's range reaches the point (the seabed's far edge
// seen at grazing incidence, whose pixels have no farther neighbour; the top of an object seen from
// below), the far end of each pixel's footprint in `to` (pixel_spread on its echo) is what counts.
bool seen_around(const Plan& plan, const Frame& to, std::uint32_t s, double cx, double cy, double r,
                 const double* slant_factor) {
    const std::uint32_t W = view_columns(plan, s), first = view_first_column(plan, s);
    if (!(cx >= 0.0 && cx < W && cy >= 0.0 && cy < plan.rows)) return false;
    const auto column = static_cast<std::int64_t>(cx), row = static_cast<std::int64_t>(cy);
    const double tolerance = plan.bin_width_m + 1e-3 * r;
    const auto each_hit = [&](const auto& test) {
        for (std::int64_t dy = -1; dy <= 1; ++dy)
            for (std::int64_t dx = -1; dx <= 1; ++dx) {
                const std::int64_t y = row + dy, x = column + dx;
                if (y < 0 || y >= plan.rows || x < 0 || x >= W) continue;
                const std::size_t q = static_cast<std::size_t>(y) * plan.columns + first + static_cast<std::size_t>(x);
                const double d = to.depth[q];
                if (d > 0.0 && test(q, d, static_cast<std::uint32_t>(y), first + static_cast<std::uint32_t>(x)))
                    return true;
            }
        return false;
    };
    // (its slant range as the echo stage reconstructs it: LabelsStage's per-pixel factor)
    if (each_hit([&](std::size_t q, double d, std::uint32_t, std::uint32_t) {
            return M::view_z_from_depth(d, plan.depth_a, plan.depth_b) * slant_factor[q] >= r - tolerance;
        }))
        return true;
    if (plan.params.range_kernel != shared::kRangeKernelFootprint || to.echo.size() != 2 * to.depth.size())
        return false;
    const double range_min = plan.config.range_min_m, inv_bin_width = 1.0 / plan.bin_width_m;
    return each_hit([&](std::size_t q, double, std::uint32_t y, std::uint32_t c) {
        const M::RangeSpread spread =
            pixel_spread<double>(plan, to.echo.data(), y, c, double(to.echo[2 * q]), range_min, inv_bin_width);
        return spread.kernel == shared::kRangeKernelFootprint &&
               range_min + (spread.origin + spread.hi) * plan.bin_width_m >= r - tolerance;
    });
}

// Whether the depth image `to` sees the point p (sonar frame, range r): some pixel of the 3 x 3 around
// its direction holds a surface at least as far as r - tolerance (a nearer surface in all nine is an
// occluder; the neighbours absorb the pixel grid's own range steps at grazing incidence). False outside
// the depth pass's coverage. With tier views each direction is seen by the view whose elevation band
// holds it (a slice's is the elevation gate, the tiers' lie beyond), as the echo counts its pixels; a
// direction past a slice's top or bottom row is then a tier view's, not hidden.
bool visible_in(const Plan& plan, const Frame& to, const double p[3], double r, const double* slant_factor) {
    const double direction[3] = {p[0] / r, p[1] / r, p[2] / r};
    const double sin_elevation = direction[2];
    const bool tiers = plan.views > plan.slices;
    for (std::uint32_t s = 0; s < plan.views; ++s) {
        // the view whose cell holds the direction (its elevation band and azimuths: in front of a slice's
        // camera, between its side planes; a tier view's wedge), where the pixel grid sees it
        const ViewGeometry& g = plan.view_geometry[s];
        if ((tiers || g.wedge) && !(sin_elevation >= g.sin_elevation_min && sin_elevation <= g.sin_elevation_max))
            continue;
        const double z = direction[0] * g.forward[0] + direction[1] * g.forward[1] + direction[2] * g.forward[2];
        if (!(z > 0.0)) continue;
        const double u = (direction[0] * g.right[0] + direction[1] * g.right[1] + direction[2] * g.right[2]) / z;
        if (g.wedge) {
            if (!(direction[1] * g.wedge_start[0] - direction[0] * g.wedge_start[1] >= 0.0 &&
                  direction[1] * g.wedge_end[0] - direction[0] * g.wedge_end[1] < 0.0))
                continue;
        } else if (!(std::abs(u) <= g.tan_half_h + 1e-12)) {
            continue;
        }
        const double v = (direction[0] * g.down[0] + direction[1] * g.down[1] + direction[2] * g.down[2]) / z;
        const double cx = (u / g.tan_half_h + 1.0) * 0.5 * view_columns(plan, s),
                     cy = (v / g.tan_half_v + 1.0) * 0.5 * plan.rows;
        return seen_around(plan, to, s, cx, cy, r, slant_factor);
    }
    return false;
}

// One labelled cell i: its point p (sonar frame of `from`) carried to `to`'s sonar frame.
void flow_cell(const FlowJob& job, std::size_t i) {
    const Plan& plan = *job.plan;
    const Frame& from = *job.from;
    const auto& a = job.a;
    const auto& b = job.b;
    const double p[3] = {from.point[3 * i], from.point[3 * i + 1], from.point[3 * i + 2]};
    double q[3] = {p[0], p[1], p[2]}; // the same pose: the point stays where it is (a flow of exactly 0)
    if (!job.same_pose) {
        // a = sonar_from_world = [R^T | -R^T t]: the world point is R (p - a's translation column)
        double world[3];
        for (int k = 0; k < 3; ++k) {
            double sum = 0.0;
            for (int m = 0; m < 3; ++m)
                sum += a[k * 4 + m] * (p[m] - a[12 + m]);
            world[k] = sum;
        }
        for (int m = 0; m < 3; ++m)
            q[m] = b[m] * world[0] + b[4 + m] * world[1] + b[8 + m] * world[2] + b[12 + m];
    }
    double bin_from, beam_from, bin_to, beam_to;
    polar_coordinates(plan, p, bin_from, beam_from, *job.buckets);
    const double r = polar_coordinates(plan, q, bin_to, beam_to, *job.buckets);
    if (std::isnan(bin_to) || std::isnan(beam_to) || !visible_in(plan, *job.to, q, r, job.slant_factor)) return;
    job.flow[2 * i] = static_cast<float>(bin_to - bin_from);
    job.flow[2 * i + 1] = static_cast<float>(beam_step(plan, beam_from, beam_to));
}

#if defined(__x86_64__) && defined(__GNUC__)
#define VKS_AVX2 __attribute__((target("avx2")))

VKS_AVX2 inline __m256d splat(double v) {
    return _mm256_set1_pd(v);
}

// polar_coordinates of four points (x, y, z lanes), into bin[4] and beam[4]; their ranges in r. The same
// operations lane by lane: the range's sqrt, bin and sine by vector, the angle (asin or atan2) and the
// beam's search per lane, the beam's fraction by vector where the angle lies between two beams
// (beam_coordinate's other cases per lane).
VKS_AVX2 void polar_coordinates4(const Plan& plan, __m256d x, __m256d y, __m256d z, const BeamBuckets& buckets,
                                 double* bin, double* beam, __m256d& r) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    r = _mm256_sqrt_pd(_mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(x, x), _mm256_mul_pd(y, y)), _mm256_mul_pd(z, z)));
    const __m256d range_min = splat(plan.config.range_min_m);
    const PointWindow window = point_window(plan);
    const __m256d in_window = _mm256_and_pd(_mm256_cmp_pd(r, splat(window.min_m), _CMP_GE_OQ),
                                            _mm256_cmp_pd(r, splat(window.max_m), _CMP_LT_OQ));
    _mm256_storeu_pd(
        bin,
        _mm256_blendv_pd(splat(nan), _mm256_div_pd(_mm256_sub_pd(r, range_min), splat(plan.bin_width_m)), in_window));
    alignas(32) double angle[4], range[4];
    _mm256_store_pd(range, r);
    if (plan.line_array) {
        // std::clamp(y / r, -1, 1), a NaN kept
        __m256d s = _mm256_div_pd(y, r);
        s = _mm256_blendv_pd(s, splat(-1.0), _mm256_cmp_pd(s, splat(-1.0), _CMP_LT_OQ));
        s = _mm256_blendv_pd(s, splat(1.0), _mm256_cmp_pd(splat(1.0), s, _CMP_LT_OQ));
        _mm256_store_pd(angle, s);
        for (double& a : angle)
            a = std::asin(a);
    } else {
        alignas(32) double xs[4], ys[4];
        _mm256_store_pd(xs, x);
        _mm256_store_pd(ys, y);
        for (int l = 0; l < 4; ++l)
            angle[l] = std::atan2(ys[l], xs[l]);
    }
    // beam_coordinate's general case by vector: double(j - 1) + (t[j - 1] - a) / (t[j - 1] - t[j]); the
    // others per lane
    const std::vector<double>& t = plan.beam_angle_rad;
    const double half = 0.5 * plan.config.hfov_deg * kDegToRad;
    alignas(32) double above[4], below[4], base[4], other[4];
    int others = 0;
    for (int l = 0; l < 4; ++l) {
        const double a = angle[l];
        if (!(range[l] > 0.0) || !between_beams(t, half, a)) {
            others |= 1 << l;
            other[l] = range[l] > 0.0 ? beam_coordinate(plan, a, buckets) : nan;
            above[l] = 1.0, below[l] = 0.0, base[l] = 0.0;
            continue;
        }
        const std::size_t j = buckets.first_below(t, a);
        above[l] = t[j - 1];
        below[l] = t[j];
        base[l] = double(j - 1);
    }
    const __m256d t_above = _mm256_load_pd(above);
    _mm256_storeu_pd(beam,
                     _mm256_add_pd(_mm256_load_pd(base), _mm256_div_pd(_mm256_sub_pd(t_above, _mm256_load_pd(angle)),
                                                                       _mm256_sub_pd(t_above, _mm256_load_pd(below)))));
    for (int l = 0; l < 4 && others != 0; ++l)
        if (others & (1 << l)) beam[l] = other[l];
}

// (d0, d1, d2) . axis, lane by lane, summed left to right
VKS_AVX2 inline __m256d dot3(__m256d d0, __m256d d1, __m256d d2, const double (&axis)[3]) {
    return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(d0, splat(axis[0])), _mm256_mul_pd(d1, splat(axis[1]))),
                         _mm256_mul_pd(d2, splat(axis[2])));
}

// visible_in of four points (q lanes, ranges r) into visible[l] for the lanes in `wanted`: the same
// operations lane by lane, the view each direction falls in and its place there by vector (the views in
// order, each lane keeping the first that holds it), the pixels around it per lane (seen_around).
VKS_AVX2 void visible_in4(const Plan& plan, const Frame& to, const double* slant_factor, const __m256d (&q)[3],
                          __m256d r, int wanted, bool (&visible)[4]) {
    const __m256d d0 = _mm256_div_pd(q[0], r), d1 = _mm256_div_pd(q[1], r), d2 = _mm256_div_pd(q[2], r);
    const bool tiers = plan.views > plan.slices;
    const __m256d none = _mm256_setzero_pd();
    __m256d taken = none, cx = none, cy = none, view = splat(-1.0);
    for (std::uint32_t s = 0; s < plan.views; ++s) {
        const ViewGeometry& g = plan.view_geometry[s];
        __m256d in = _mm256_andnot_pd(taken, _mm256_castsi256_pd(_mm256_set1_epi64x(-1)));
        if (tiers || g.wedge)
            in = _mm256_and_pd(in, _mm256_and_pd(_mm256_cmp_pd(d2, splat(g.sin_elevation_min), _CMP_GE_OQ),
                                                 _mm256_cmp_pd(d2, splat(g.sin_elevation_max), _CMP_LE_OQ)));
        if (_mm256_movemask_pd(in) == 0) continue;
        const __m256d z = dot3(d0, d1, d2, g.forward);
        in = _mm256_and_pd(in, _mm256_cmp_pd(z, none, _CMP_GT_OQ));
        const __m256d u = _mm256_div_pd(dot3(d0, d1, d2, g.right), z);
        if (g.wedge) {
            const __m256d after_start =
                _mm256_sub_pd(_mm256_mul_pd(d1, splat(g.wedge_start[0])), _mm256_mul_pd(d0, splat(g.wedge_start[1])));
            const __m256d after_end =
                _mm256_sub_pd(_mm256_mul_pd(d1, splat(g.wedge_end[0])), _mm256_mul_pd(d0, splat(g.wedge_end[1])));
            in = _mm256_and_pd(in, _mm256_and_pd(_mm256_cmp_pd(after_start, none, _CMP_GE_OQ),
                                                 _mm256_cmp_pd(after_end, none, _CMP_LT_OQ)));
        } else {
            const __m256d abs_u = _mm256_andnot_pd(splat(-0.0), u);
            in = _mm256_and_pd(in, _mm256_cmp_pd(abs_u, splat(g.tan_half_h + 1e-12), _CMP_LE_OQ));
        }
        if (_mm256_movemask_pd(in) == 0) continue;
        const __m256d v = _mm256_div_pd(dot3(d0, d1, d2, g.down), z);
        const __m256d half = splat(0.5), one = splat(1.0);
        const __m256d x = _mm256_mul_pd(_mm256_mul_pd(_mm256_add_pd(_mm256_div_pd(u, splat(g.tan_half_h)), one), half),
                                        splat(double(view_columns(plan, s))));
        const __m256d y = _mm256_mul_pd(_mm256_mul_pd(_mm256_add_pd(_mm256_div_pd(v, splat(g.tan_half_v)), one), half),
                                        splat(double(plan.rows)));
        cx = _mm256_blendv_pd(cx, x, in);
        cy = _mm256_blendv_pd(cy, y, in);
        view = _mm256_blendv_pd(view, splat(double(s)), in);
        taken = _mm256_or_pd(taken, in);
        if (_mm256_movemask_pd(taken) == 15) break;
    }
    alignas(32) double xs[4], ys[4], views[4], range[4];
    _mm256_store_pd(xs, cx);
    _mm256_store_pd(ys, cy);
    _mm256_store_pd(views, view);
    _mm256_store_pd(range, r);
    for (int l = 0; l < 4; ++l)
        visible[l] = (wanted & (1 << l)) && views[l] >= 0.0 &&
                     seen_around(plan, to, static_cast<std::uint32_t>(views[l]), xs[l], ys[l], range[l], slant_factor);
}

// flow_cell of four labelled cells side by side.
VKS_AVX2 void flow_cells4(const FlowJob& job, const std::size_t (&cells)[4]) {
    const Plan& plan = *job.plan;
    const Frame& from = *job.from;
    const auto& a = job.a;
    const auto& b = job.b;
    alignas(32) double p[3][4];
    for (int l = 0; l < 4; ++l)
        for (int m = 0; m < 3; ++m)
            p[m][l] = from.point[3 * cells[l] + m];
    const __m256d px = _mm256_load_pd(p[0]), py = _mm256_load_pd(p[1]), pz = _mm256_load_pd(p[2]);
    __m256d q[3] = {px, py, pz}; // the same pose: flow_cell's exact 0
    if (!job.same_pose) {
        __m256d world[3];
        for (int k = 0; k < 3; ++k) {
            __m256d sum = _mm256_setzero_pd();
            for (int m = 0; m < 3; ++m)
                sum = _mm256_add_pd(
                    sum, _mm256_mul_pd(splat(a[k * 4 + m]), _mm256_sub_pd(_mm256_load_pd(p[m]), splat(a[12 + m]))));
            world[k] = sum;
        }
        for (int m = 0; m < 3; ++m)
            q[m] = _mm256_add_pd(_mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(splat(b[m]), world[0]),
                                                             _mm256_mul_pd(splat(b[4 + m]), world[1])),
                                               _mm256_mul_pd(splat(b[8 + m]), world[2])),
                                 splat(b[12 + m]));
    }
    alignas(32) double bin_from[4], beam_from[4], bin_to[4], beam_to[4];
    __m256d r_from, r_to;
    polar_coordinates4(plan, px, py, pz, *job.buckets, bin_from, beam_from, r_from);
    polar_coordinates4(plan, q[0], q[1], q[2], *job.buckets, bin_to, beam_to, r_to);
    int wanted = 0;
    for (int l = 0; l < 4; ++l)
        wanted |= (!std::isnan(bin_to[l]) && !std::isnan(beam_to[l])) << l;
    bool visible[4];
    visible_in4(plan, *job.to, job.slant_factor, q, r_to, wanted, visible);
    for (int l = 0; l < 4; ++l) {
        if (!visible[l]) continue;
        job.flow[2 * cells[l]] = static_cast<float>(bin_to[l] - bin_from[l]);
        job.flow[2 * cells[l] + 1] = static_cast<float>(beam_step(plan, beam_from[l], beam_to[l]));
    }
}
#undef VKS_AVX2
#else
void flow_cells4(const FlowJob&, const std::size_t (&)[4]) {}
#endif

} // namespace

void flow_cells(const FlowJob& job, std::size_t begin, std::size_t end) {
    const Plan& plan = *job.plan;
    const Frame& from = *job.from;
    float* flow = job.flow;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const std::size_t cells = static_cast<std::size_t>(plan.bins) * plan.beams;
    const bool any = from.instance.size() == cells && !job.to->depth.empty();
    const bool by_four = any && use_avx2(plan.config);
    std::size_t batch[4];
    int batched = 0;
    for (std::size_t i = begin; i < end; ++i) {
        flow[2 * i] = flow[2 * i + 1] = nan;
        if (!any || from.instance[i] == 0) continue;
        if (!by_four) {
            flow_cell(job, i);
            continue;
        }
        batch[batched++] = i;
        if (batched == 4) {
            flow_cells4(job, batch);
            batched = 0;
        }
    }
    for (int l = 0; l < batched; ++l)
        flow_cell(job, batch[l]);
}

} // namespace vksonar::cpu
