// LabelsStage::flow's cells (labels_flow.h): each labelled point of `from` moved to the pose of `to`, its
// polar coordinates in either frame and whether `to`'s depth image sees it.
#include "stages/labels_flow.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/angles.h"
#include "core/sonar_math.hpp"

namespace vksonar::cpu {

namespace {
using M = Math<double>;
} // namespace

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

std::size_t BeamBuckets::first_below(const std::vector<double>& t, double a) const {
    // From the bucket above a's (a rounding of a's bucket by one is covered): every j before that bucket's
    // first has t[j] >= its upper edge > a, so the answer is there or after it. No buckets, or a NaN or
    // huge quotient: from the first beam.
    const double u = (a - low) * per_rad;
    std::size_t j = 0;
    if (u >= 0.0 && u + 1.0 < double(first.size())) j = first[static_cast<std::size_t>(u) + 1];
    while (j < t.size() && !(t[j] < a))
        ++j;
    return j;
}

namespace {

// The fractional beam index of steering angle a on the beam table (strictly decreasing, port first):
// linear between beam centres, extrapolated by the edge spacing up to the fan's edge; NaN outside it.
double beam_coordinate(const Plan& plan, double a, const BeamBuckets& buckets) {
    const std::vector<double>& t = plan.beam_angle_rad;
    const std::size_t n = t.size();
    const double half = 0.5 * plan.config.hfov_deg * kDegToRad;
    if (n == 0 || !(std::abs(a) <= half)) return std::numeric_limits<double>::quiet_NaN();
    if (n == 1) return 0.0;
    if (a >= t[0]) return (t[0] - a) / (t[0] - t[1]);
    if (a <= t[n - 1]) return double(n - 1) + (t[n - 1] - a) / (t[n - 2] - t[n - 1]);
    // first j with t[j] < a (t decreasing): the point lies between beams j - 1 and j
    const std::size_t j = buckets.first_below(t, a);
    return double(j - 1) + (t[j - 1] - a) / (t[j - 1] - t[j]);
}

// The point p (sonar frame) as (bin, beam) coordinates: bin b covers [b, b + 1) (cell k's centre at
// k + 0.5); NaN outside the window.
void polar_coordinates(const Plan& plan, const double p[3], double& bin, double& beam, const BeamBuckets& buckets) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double r = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    bin = r >= plan.config.range_min_m && r < plan.config.range_max_m ? (r - plan.config.range_min_m) / plan.bin_width_m
                                                                      : nan;
    // The beam a direction is heard on: its cone (line array, the sine along the y axis) or its azimuth.
    const double angle = plan.line_array ? std::asin(std::clamp(p[1] / r, -1.0, 1.0)) : std::atan2(p[1], p[0]);
    beam = r > 0.0 ? beam_coordinate(plan, angle, buckets) : nan;
}

// visible_in's test in view s, at the point's place (cx, cy) in the view's pixel grid: some pixel of the
// 3 x 3 around it holds a surface at least as far as r - tolerance. False outside the grid.
bool seen_around(const Plan& plan, const Frame& to, std::uint32_t s, double cx, double cy, double r,
                 const double* slant_factor) {
    const std::uint32_t W = view_columns(plan, s), first = view_first_column(plan, s);
    if (!(cx >= 0.0 && cx < W && cy >= 0.0 && cy < plan.rows)) return false;
    const auto column = static_cast<std::int64_t>(cx), row = static_cast<std::int64_t>(cy);
    const double tolerance = plan.bin_width_m + 1e-3 * r;
    for (std::int64_t dy = -1; dy <= 1; ++dy)
        for (std::int64_t dx = -1; dx <= 1; ++dx) {
            const std::int64_t y = row + dy, x = column + dx;
            if (y < 0 || y >= plan.rows || x < 0 || x >= W) continue;
            const std::size_t q = static_cast<std::size_t>(y) * plan.columns + first + static_cast<std::size_t>(x);
            const double d = to.depth[q];
            if (!(d > 0.0)) continue;
            // (its slant range as the echo stage reconstructs it: LabelsStage's per-pixel factor)
            const double range = M::view_z_from_depth(d, plan.depth_a, plan.depth_b) * slant_factor[q];
            if (range >= r - tolerance) return true;
        }
    return false;
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

} // namespace

namespace {

// One labelled cell i: its point p (sonar frame of `from`) carried to `to`'s sonar frame.
void flow_cell(const FlowJob& job, std::size_t i) {
    const Plan& plan = *job.plan;
    const Frame& from = *job.from;
    const auto& a = job.a;
    const auto& b = job.b;
    const double p[3] = {from.point[3 * i], from.point[3 * i + 1], from.point[3 * i + 2]};
    // a = sonar_from_world = [R^T | -R^T t]: the world point is R (p - a's translation column)
    double world[3];
    for (int k = 0; k < 3; ++k) {
        double sum = 0.0;
        for (int m = 0; m < 3; ++m)
            sum += a[k * 4 + m] * (p[m] - a[12 + m]);
        world[k] = sum;
    }
    double q[3];
    for (int m = 0; m < 3; ++m)
        q[m] = b[m] * world[0] + b[4 + m] * world[1] + b[8 + m] * world[2] + b[12 + m];
    double bin_from, beam_from, bin_to, beam_to;
    polar_coordinates(plan, p, bin_from, beam_from, *job.buckets);
    polar_coordinates(plan, q, bin_to, beam_to, *job.buckets);
    const double r = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
    if (std::isnan(bin_to) || std::isnan(beam_to) || !visible_in(plan, *job.to, q, r, job.slant_factor)) return;
    job.flow[2 * i] = static_cast<float>(bin_to - bin_from);
    job.flow[2 * i + 1] = static_cast<float>(beam_to - beam_from);
}

} // namespace

void flow_cells(const FlowJob& job, std::size_t begin, std::size_t end) {
    const Plan& plan = *job.plan;
    const Frame& from = *job.from;
    float* flow = job.flow;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const std::size_t cells = static_cast<std::size_t>(plan.bins) * plan.beams;
    const bool any = from.instance.size() == cells && !job.to->depth.empty();
    for (std::size_t i = begin; i < end; ++i) {
        flow[2 * i] = flow[2 * i + 1] = nan;
        if (any && from.instance[i] != 0) flow_cell(job, i);
    }
}

} // namespace vksonar::cpu
