// Stage 4a, per-column range profiles (docs/pipeline.md §4). One invocation owns one pixel column and
// walks its rows top to bottom, so every profile cell has exactly one writer and a fixed summation
// order: no atomics, bit-identical run to run. With the line-array beam geometry the profiles are per
// cone column instead, each invocation gathering the pixels of its cone columns (gather_cone_columns).
//
// Bin lanes: on a GPU one invocation per column leaves the device nearly idle (1k invocations on a
// 100k-lane chip, each walking every row in turn: 3 ms on an H200). There kBinLanes invocations (one
// subgroup) share a column: each walks the same pixels (the loads coincide, one transaction for all)
// and adds only to the bins k with k % kBinLanes == its lane. Every cell keeps one writer and the order
// of its additions, so the frame is bit-identical for any kBinLanes; lavapipe runs 1 (its lanes are a
// loop over the same work).
// The host zeroes `profiles` (vkCmdFillBuffer) first: a memset is far cheaper than per-invocation
// strided stores.
//
// GPU layout: profiles[column * bins_padded + bin] (bins fastest, padded to a multiple of 4), so that
// resample.comp loads four bins of a column as one vec4. The host transposes to the public
// bins x columns layout when profiles are saved.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"
#define REAL float
#define VKS_ATAN2 atan
#include "sonar_math.h"
#include "sonar_kernels.h"

layout(local_size_x = kWorkgroupSize) in;

layout(constant_id = kSpecRangeKernel) const uint kRangeKernel = kRangeKernelFootprint; // params.range_kernel
layout(constant_id = kSpecEchoHalf) const uint kEchoHalf = 0u;                      // params.echo_half
layout(constant_id = kSpecTierViews) const uint kTierViews = 0u; // Plan::views > slices
layout(constant_id = kSpecLineArray) const uint kLineArray = 0u;                    // params.line_array
layout(constant_id = kSpecPerInvocation) const uint kConesPerInvocation = 4u;       // line_array (see below)
layout(constant_id = kSpecSubpixel) const uint kSubpixel = 0u;                     // Plan::subpixel_capacity > 0
layout(constant_id = kSpecBinLanes) const uint kBinLanes = 1u;                      // a power of 2 (see above)
layout(constant_id = kSpecGatherRows) const uint kGatherRows = 0u;     // gather_block_rows (below)
layout(constant_id = kSpecRowCandidates) const uint kRowCandidates = 1u;
layout(constant_id = kSpecSharedBins) const uint kSharedBins = 1u;
// (constants, not uniforms: lavapipe would run the loads and stores of every kernel, src/vk/pipelines.h)

layout(std140, binding = kBindingParams) uniform ParamsBlock { SonarParams params; };
// The rows [row_begin, row_end) this dispatch walks (ProfileRowBand; the host splits the rows into bands
// where one invocation would loop more often than lavapipe lets it: src/vk/profile_bands.h). Each band
// adds to the profiles after the one before, so every cell's additions keep their order. The walks that
// take rows in blocks (kGatherRows) always get all of them.
layout(push_constant, std430) uniform ProfileRowsBlock { ProfileRowBand band; };
// The frame's status word: kStatusLoopLimit where loops_ran_out() (below).
layout(std430, binding = kBindingStatus) buffer StatusBuffer { uint status[]; };

// Whether the device ended this invocation's loops early. Lavapipe counts every loop iteration of an
// invocation against one limit (65535) and, once it is spent, ends each loop at its next turn without a
// word: this loop of band.loop_check (2) turns then stops after one. The bands keep the walks well within
// the limit by an estimate (src/vk/profile_bands.h); this says when a scene beat the estimate, so that the
// host refuses the frame instead of passing on profiles with rows missing.
bool loops_ran_out() {
    uint turns = 0u;
    for (uint i = 0u; i < band.loop_check; ++i) {
        ++turns;
    }
    return turns != band.loop_check;
}
layout(std430, binding = kBindingEcho) readonly buffer EchoBuffer { vec2 echo2[]; };
layout(std430, binding = kBindingEcho) readonly buffer EchoHalfBuffer { uint echo_half2[]; }; // accuracy.intermediates = fp16

vec2 load_echo(uint p) {
    if (kEchoHalf != 0u) {
        vec2 v = unpackHalf2x16(echo_half2[p]);
        return vec2(v.x / params.echo_scale, v.y);
    }
    return echo2[p];
}
layout(std430, binding = kBindingProfiles) buffer ProfileBuffer { float profiles[]; };

// This invocation's lane among the kBinLanes sharing its column, and its first bin of a spread: the
// first k >= k_first with k % kBinLanes == lane.
uint bin_lane() {
    return gl_GlobalInvocationID.x & (kBinLanes - 1u);
}
int first_lane_bin(int k_first) {
    return k_first + int((bin_lane() - uint(k_first)) & (kBinLanes - 1u));
}

// The ranges of pixel (row, column)'s row neighbours left and right (x, y), 0 where there is none in its
// view (its columns [view.x, view.y); across a view's edge lies another camera's image): what
// range_spread's extent across the column reads (src/stages/pixel_spread.h row_neighbours).
vec2 row_neighbour_ranges(uint row, uint column, uvec2 view) {
    uint p = row * params.columns + column;
    float left = column > view.x ? load_echo(p - 1u).y : 0.0;
    float right = column + 1u < view.y ? load_echo(p + 1u).y : 0.0;
    return vec2(left, right);
}

// The columns [first, end) of column c's view (no integer divide per pixel: sonar_math.h
// view_of_pixel_column).
uvec2 view_columns_of(uint c) {
    uint view = view_of_pixel_column(c, params.slices, params.slice_columns, 1.0 / float(params.slice_columns),
                                     1.0 / float(max(params.tier_columns, 1u)));
    uint first = first_column_of_view(view, params.slices, params.slice_columns, params.tier_columns);
    return uvec2(first, first + columns_of_view(view, params.slices, params.slice_columns, params.tier_columns));
}

// The range spread of pixel (row, column) with echo er, over the five-row window of its column and its
// row neighbours.
// `precise` inside range_spread: the bin coordinates and shares round exactly as the CPU's.
RangeSpread pixel_spread(uint row, uint column, vec2 er) {
    uint columns = params.columns;
    vec2 up2 = row >= 2u ? load_echo((row - 2u) * columns + column) : vec2(0.0);
    vec2 up = row >= 1u ? load_echo((row - 1u) * columns + column) : vec2(0.0);
    vec2 down = row + 1u < params.rows ? load_echo((row + 1u) * columns + column) : vec2(0.0);
    vec2 down2 = row + 2u < params.rows ? load_echo((row + 2u) * columns + column) : vec2(0.0);
    vec2 across = row_neighbour_ranges(row, column, view_columns_of(column));
    return range_spread(kRangeKernel, up2, up, er, down, down2, across.x, across.y, params.range_min_m,
                        params.inv_bin_width_m, params.edge_relative_jump, params.bins, params.absorption_per_bin);
}

// Each pixel's cone coordinate (sonar_kernels.h cone_coord), computed once by the plan: the CPU
// backend reads the same table, so both put a pixel into the same cone columns with the same shares
// (Vulkan allows GLSL's asin an error of 4096 ulps, 5e-4 rad near 1: a fifth of the default's cone column).
layout(std430, binding = kBindingConeCoord) readonly buffer ConeCoordBuffer { float cone_coords[]; };

// line_array: one invocation owns the cone columns [first_cone, end_cone) (kConesPerInvocation of
// them) and gathers, row by row (top to bottom) and within a row by increasing pixel column, every
// pixel whose cone coordinate lies within one column of them; each such pixel's window is loaded and
// its range spread computed once, then added to the (at most two; a tier view's pixel: those its extent
// touches) of its cone columns this invocation owns. So every profile cell receives its additions in the order of the CPU backend's scatter
// (src/stages/cpu_beamform_profile.cpp): rows, then pixel columns, then bins. Along a row of one view the cone
// coordinate increases with the pixel column (the plan checks it), so in each view the first such
// pixel is found by a binary search on the first row and then moves by a few columns from row to row.
// The share of cone column `cone` of pixel column c of a row (row_start: its first pixel): cone_share at
// its cone coordinate, a tier view's pixel's by its cone extent (sonar_kernels.h cone_extent_share, the
// extent as src/core/tier_extent.h reads it from the same table).
float pixel_cone_share(uint row_start, uint c, int cone, int count) {
    float x = cone_coords[row_start + c];
    uint slices_end = params.slices * params.slice_columns;
    if (c < slices_end || params.tier_columns == 0u) {
        return cone_share(x, cone, count);
    }
    uint begin = slices_end + ((c - slices_end) / params.tier_columns) * params.tier_columns;
    bool has_previous = c > begin;
    bool has_next = c + 1u < begin + params.tier_columns;
    float previous = has_previous ? cone_coords[row_start + c - 1u] : x;
    float next = has_next ? cone_coords[row_start + c + 1u] : x;
    return cone_extent_share(x, cone_extent_low(previous, x, next, has_previous, has_next),
                             cone_extent_high(previous, x, next, has_previous, has_next), cone, count);
}

// reach: 0 for the slices, Plan::tier_cone_reach for a tier view (its pixels feed the cone columns their
// extent touches).
void gather_view(uint row, uint view_begin, uint view_end, inout uint first, uint first_cone, uint end_cone,
                 float reach) {
    uint row_start = row * params.columns;
    float lo = float(first_cone) - 1.0 - reach;
    float hi = float(end_cone) + reach;
    int count = int(params.profile_columns);
    while (first > view_begin && cone_coords[row_start + first - 1u] > lo) {
        --first;
    }
    while (first < view_end && !(cone_coords[row_start + first] > lo)) {
        ++first;
    }
    for (uint c = first; c < view_end; ++c) {
        float x = cone_coords[row_start + c];
        if (!(x < hi)) {
            break;
        }
        if (reach > 0.0) {
            // a tier view's pixel: the cone columns its extent touches, those of them this invocation owns
            vec2 er = load_echo(row_start + c);
            if (!(er.x > 0.0)) {
                continue;
            }
            bool has_previous = c > view_begin;
            bool has_next = c + 1u < view_end;
            float previous = has_previous ? cone_coords[row_start + c - 1u] : x;
            float next = has_next ? cone_coords[row_start + c + 1u] : x;
            float extent_lo = cone_extent_low(previous, x, next, has_previous, has_next);
            float extent_hi = cone_extent_high(previous, x, next, has_previous, has_next);
            // the cells [c - 0.5, c + 0.5] its extent meets (the tent's two columns where it has no width)
            bool wide = extent_hi > extent_lo;
            int cone_first = max(wide ? int(floor(extent_lo + 0.5)) : int(floor(x)), int(first_cone));
            int cone_last = min(wide ? int(floor(extent_hi + 0.5)) : int(floor(x)) + 1, int(end_cone) - 1);
            bool spread_made = false;
            RangeSpread spread;
            for (int cone = cone_first; cone <= cone_last; ++cone) {
                float weight = cone_extent_share(x, extent_lo, extent_hi, cone, count);
                if (!(weight > 0.0)) {
                    continue;
                }
                if (!spread_made) {
                    spread = pixel_spread(row, c, er);
                    spread_made = true;
                }
                precise float weighted = weight * er.x;
                uint base = uint(cone) * params.bins_padded;
                for (int k = first_lane_bin(spread.k_first); k <= spread.k_last; k += int(kBinLanes)) {
                    precise float add = range_share(spread, k) * weighted;
                    profiles[base + uint(k)] += add;
                }
            }
            continue;
        }
        // its cone columns floor(x) and floor(x) + 1, those of them this invocation owns
        int below = int(floor(x));
        int cone_a = max(below, int(first_cone));
        int cone_b = min(below + 1, int(end_cone) - 1);
        float weight_a = cone_a <= cone_b ? cone_share(x, cone_a, count) : 0.0;
        float weight_b = cone_b > cone_a ? cone_share(x, cone_b, count) : 0.0;
        vec2 er = load_echo(row_start + c);
        if (!(er.x > 0.0) || !(weight_a > 0.0 || weight_b > 0.0)) {
            continue;
        }
        RangeSpread spread = pixel_spread(row, c, er);
        precise float weighted_a = weight_a * er.x;
        precise float weighted_b = weight_b * er.x;
        uint base_a = uint(cone_a) * params.bins_padded;
        uint base_b = uint(cone_b) * params.bins_padded;
        for (int k = first_lane_bin(spread.k_first); k <= spread.k_last; k += int(kBinLanes)) {
            float share = range_share(spread, k);
            if (weight_a > 0.0) {
                precise float add = share * weighted_a;
                profiles[base_a + uint(k)] += add;
            }
            if (weight_b > 0.0) {
                precise float add = share * weighted_b;
                profiles[base_b + uint(k)] += add;
            }
        }
    }
}

// The first pixel column of [begin, end) on the row starting at pixel row_start with a cone coordinate
// above lo (binary search).
uint first_above(uint row_start, uint begin, uint end, float lo) {
    while (begin < end) {
        uint mid = (begin + end) / 2u;
        if (cone_coords[row_start + mid] > lo) {
            end = mid;
        } else {
            begin = mid + 1u;
        }
    }
    return begin;
}

// The slices of the main band are one run of columns along which the cone coordinate increases (they
// join at their seams); each tier view of the vertical side lobes is a run of its own.
void gather_cone_columns(uint first_cone, uint end_cone) {
    uint slices_end = params.slices * params.slice_columns;
    uint width = params.tier_columns; // each tier view's
    uint tiers = kTierViews != 0u && width > 0u ? (params.columns - slices_end) / width : 0u;
    float lo = float(first_cone) - 1.0;
    float tier_lo = lo - params.tier_cone_reach;
    uint row_start = band.row_begin * params.columns; // each view's first column found on the band's first row
    uint first_slices = first_above(row_start, 0u, slices_end, lo);
    uint first_tier[kMaxViews];
    for (uint t = 0u; t < tiers; ++t) {
        uint begin = slices_end + t * width;
        first_tier[t] = first_above(row_start, begin, begin + width, tier_lo);
    }
    for (uint row = band.row_begin; row < band.row_end; ++row) {
        gather_view(row, 0u, slices_end, first_slices, first_cone, end_cone, 0.0);
        for (uint t = 0u; t < tiers; ++t) {
            uint begin = slices_end + t * width;
            gather_view(row, begin, begin + width, first_tier[t], first_cone, end_cone, params.tier_cone_reach);
        }
    }
}

// line_array on a GPU (kGatherRows): gather_cone_columns walks the rows one after another, every pixel a
// chain of dependent loads and its spread computed by all kBinLanes lanes alike (0.53 ms of an H100's
// 0.67 ms beamform). Here a workgroup's two cone columns (kBinLanes = 32 lanes each) take 32 rows at
// once: each lane finds its own row's pixels (from where the block before left each view's first
// column), then the lanes compute the block's spreads 32 at a time, and then add them in order (rows,
// views, columns, as gather_view), each lane its own bins, into the column's profile in shared memory.
// Every cell keeps its one writer and the order of its additions: the same bits as gather_cone_columns.
// The host turns it on where a row gives a cone column at most kRowCandidates pixels and the
// accumulators fit the device's shared memory (src/vk/vulkan_backend.cpp).
const uint kBlockRows = 32u; // = kBinLanes where kGatherRows is on
shared float block_profile[2u * kSharedBins];
shared uint block_column[2u * kBlockRows * kRowCandidates]; // each row's pixels' columns, in gather order
shared uint block_count[2u * kBlockRows];
shared uint block_first[2u * (kMaxViews + 1u)];      // each view's first column on the block's first row
shared uint block_next_first[2u * (kMaxViews + 1u)]; // ... on its last row
shared RangeSpread round_spread[2u * kBlockRows];
shared float round_energy[2u * kBlockRows]; // cone share x energy
// the shares of each spread's first kRoundShares bins, computed with the spread (most footprints span
// one to three bins), so that the adding loop, which runs one entry after another, mostly only adds
const uint kRoundShares = 4u;
shared float round_share[2u * kBlockRows * kRoundShares];

// The adding loop of a round: this lane's bins of the round's `entries` spreads, in order, into its side's
// profile (the first kRoundShares shares of each made with its spread, the rest here); with `lit_only`
// the slots whose block_count is 0 hold no spread.
void add_round(uint side, uint entries, bool lit_only) {
    for (uint i = 0u; i < entries; ++i) {
        uint entry = side * kBlockRows + i;
        if (lit_only && block_count[entry] == 0u) {
            continue;
        }
        int k_first = round_spread[entry].k_first;
        int k_last = round_spread[entry].k_last;
        float weighted = round_energy[entry];
        for (int k = first_lane_bin(k_first); k <= k_last; k += int(kBinLanes)) {
            uint nth = uint(k - k_first);
            float share =
                nth < kRoundShares ? round_share[entry * kRoundShares + nth] : range_share(round_spread[entry], k);
            precise float add = share * weighted;
            block_profile[side * kSharedBins + uint(k)] += add;
        }
    }
}

// A spread and its first shares into this lane's round slot.
void put_round(uint slot, RangeSpread spread, float weighted) {
    round_spread[slot] = spread;
    round_energy[slot] = weighted;
    for (int i = 0; i < int(kRoundShares) && spread.k_first + i <= spread.k_last; ++i) {
        round_share[slot * kRoundShares + uint(i)] = range_share(spread, spread.k_first + i);
    }
}

// Row `row`'s pixels in view [view_begin, view_end) that feed cone column `cone` (as gather_view finds
// them, from the column `first` the block before left), appended to this lane's list; returns the view's
// first column for this row.
uint list_view(uint row, uint view_begin, uint view_end, uint first, uint cone, uint list, inout uint n, float reach) {
    uint row_start = row * params.columns;
    float lo = float(cone) - 1.0 - reach;
    float hi = float(cone) + 1.0 + reach;
    int count = int(params.profile_columns);
    while (first > view_begin && cone_coords[row_start + first - 1u] > lo) {
        --first;
    }
    while (first < view_end && !(cone_coords[row_start + first] > lo)) {
        ++first;
    }
    for (uint c = first; c < view_end; ++c) {
        float x = cone_coords[row_start + c];
        if (!(x < hi)) {
            break;
        }
        if (load_echo(row_start + c).x > 0.0 && pixel_cone_share(row_start, c, int(cone), count) > 0.0 &&
            n < kRowCandidates) {
            block_column[list + n] = c;
            ++n;
        }
    }
    return first;
}

void gather_block_rows(uint cone, bool owned) {
    uint side = gl_LocalInvocationID.x / kBlockRows; // which of the workgroup's two cone columns
    uint lane = gl_LocalInvocationID.x % kBlockRows;
    uint slices_end = params.slices * params.slice_columns;
    uint width = params.tier_columns; // each tier view's
    uint tiers = kTierViews != 0u && width > 0u ? (params.columns - slices_end) / width : 0u;
    uint firsts = side * (kMaxViews + 1u);
    float lo = float(cone) - 1.0;
    float tier_lo = lo - params.tier_cone_reach;
    for (uint k = lane; k < kSharedBins; k += kBlockRows) {
        block_profile[side * kSharedBins + k] = 0.0;
    }
    if (lane == 0u) {
        block_first[firsts] = first_above(0u, 0u, slices_end, lo);
        for (uint t = 0u; t < tiers; ++t) {
            uint begin = slices_end + t * width;
            block_first[firsts + 1u + t] = first_above(0u, begin, begin + width, tier_lo);
        }
    }
    barrier();
    int count = int(params.profile_columns);
    for (uint row0 = 0u; row0 < params.rows; row0 += kBlockRows) {
        // This lane's row: its pixels, in gather order.
        uint row = row0 + lane;
        uint list = (side * kBlockRows + lane) * kRowCandidates;
        uint n = 0u;
        uint last_row = min(row0 + kBlockRows, params.rows) - 1u;
        if (owned && row < params.rows) {
            // the last row leaves each view's first column for the next block (block_next_first: the
            // other lanes are still reading block_first)
            bool last = row == last_row;
            uint f = list_view(row, 0u, slices_end, block_first[firsts], cone, list, n, 0.0);
            if (last) {
                block_next_first[firsts] = f;
            }
            for (uint t = 0u; t < tiers; ++t) {
                uint begin = slices_end + t * width;
                f = list_view(row, begin, begin + width, block_first[firsts + 1u + t], cone, list, n,
                              params.tier_cone_reach);
                if (last) {
                    block_next_first[firsts + 1u + t] = f;
                }
            }
        }
        block_count[side * kBlockRows + lane] = n;
        barrier();
        if (lane == 0u) {
            for (uint v = 0u; v <= tiers; ++v) {
                block_first[firsts + v] = block_next_first[firsts + v];
            }
        }
        // The block's pixels, 32 at a time: spreads in parallel, then added in order.
        uint total = 0u;
        uint most = 0u;
        for (uint h = 0u; h < 2u; ++h) {
            uint sum = 0u;
            for (uint r = 0u; r < kBlockRows; ++r) {
                sum += block_count[h * kBlockRows + r];
            }
            if (h == side) {
                total = sum;
            }
            most = max(most, sum);
        }
        for (uint done = 0u; done < most; done += kBlockRows) {
            uint slot = side * kBlockRows + lane;
            uint index = done + lane;
            if (owned && index < total) {
                uint r = 0u;
                while (index >= block_count[side * kBlockRows + r]) {
                    index -= block_count[side * kBlockRows + r];
                    ++r;
                }
                uint c = block_column[(side * kBlockRows + r) * kRowCandidates + index];
                uint pixel_row = row0 + r;
                uint p = pixel_row * params.columns + c;
                vec2 er = load_echo(p);
                precise float weighted = pixel_cone_share(pixel_row * params.columns, c, int(cone), count) * er.x;
                put_round(slot, pixel_spread(pixel_row, c, er), weighted);
            }
            barrier();
            uint entries = owned ? min(total - min(total, done), kBlockRows) : 0u;
            add_round(side, entries, false);
            barrier();
        }
        barrier(); // block_first is the next block's (where there was no round to pass a barrier)
    }
    if (owned) {
        uint base = cone * params.bins_padded;
        for (uint k = lane; k < params.bins_padded; k += kBlockRows) {
            profiles[base + k] = block_profile[side * kSharedBins + k];
        }
    }
}

// The planar profile on a GPU (kGatherRows): as gather_block_rows, a workgroup's two pixel columns 32
// rows at a time, each lane one row's spread, then added in row order; the same sums as main()'s walk.
void column_block_rows(uint column, bool owned) {
    uint side = gl_LocalInvocationID.x / kBlockRows;
    uint lane = gl_LocalInvocationID.x % kBlockRows;
    for (uint k = lane; k < kSharedBins; k += kBlockRows) {
        block_profile[side * kSharedBins + k] = 0.0;
    }
    barrier();
    for (uint row0 = 0u; row0 < params.rows; row0 += kBlockRows) {
        uint row = row0 + lane;
        uint lit = 0u; // this lane's row has a spread (an echo)
        if (owned && row < params.rows) {
            vec2 er = load_echo(row * params.columns + column);
            if (er.x > 0.0) {
                put_round(side * kBlockRows + lane, pixel_spread(row, column, er), er.x);
                lit = 1u;
            }
        }
        block_count[side * kBlockRows + lane] = lit;
        barrier();
        add_round(side, owned ? kBlockRows : 0u, true);
        barrier();
    }
    if (owned) {
        uint base = column * params.bins_padded;
        for (uint k = lane; k < params.bins_padded; k += kBlockRows) {
            profiles[base + k] = block_profile[side * kSharedBins + k];
        }
    }
}

// The frame's sub-pixel returns (src/core/subpixel.h): uints, the profile columns' first returns
// (profile_columns + 1), the silent material, then from the next multiple of 4 the returns, four words
// each (SubpixelReturn). Each column adds its own after its pixels, so it stays the only writer of its
// cells; the depth image tells whether a nearer surface hides a return (subpixel_visible).
layout(std430, binding = kBindingSubpixel) readonly buffer SubpixelBuffer { uint subpixel[]; };
layout(std430, binding = kBindingDepth) readonly buffer DepthBuffer { float depth[]; };
layout(std430, binding = kBindingMaterialId) readonly buffer MaterialIdBuffer { uint material_id[]; };

void add_subpixel(uint column) {
    uint first = subpixel[column];
    uint end = subpixel[column + 1u];
    uint silent = subpixel[params.profile_columns + 1u];
    uint base = (params.profile_columns + 5u) & ~3u;
    for (uint i = first; i < end; ++i) {
        uint w = base + 4u * i;
        uint pixel = subpixel[w];
        float range_m = uintBitsToFloat(subpixel[w + 1u]);
        float e = uintBitsToFloat(subpixel[w + 2u]);
        float view_z = uintBitsToFloat(subpixel[w + 3u]);
        if (!subpixel_visible(depth[pixel], material_id[pixel], silent, view_z, params.depth_a, params.depth_b)) {
            continue;
        }
        RangeSpread spread = range_spread(kRangeKernelTent, vec2(0.0), vec2(0.0), vec2(e, range_m), vec2(0.0),
                                          vec2(0.0), 0.0, 0.0, params.range_min_m, params.inv_bin_width_m, 0.0,
                                          params.bins, 0.0);
        for (int k = first_lane_bin(spread.k_first); k <= spread.k_last; k += int(kBinLanes)) {
            precise float add = range_share(spread, k) * e;
            profiles[column * params.bins_padded + uint(k)] += add;
        }
    }
}

void main() {
    uint unit = gl_GlobalInvocationID.x / kBinLanes; // a pixel column, or a run of cone columns
    if (kLineArray != 0u && kGatherRows != 0u) { // one cone column per unit; every lane to the end (barriers)
        bool owned = unit < params.profile_columns;
        gather_block_rows(unit, owned);
        if (kSubpixel != 0u && owned) {
            add_subpixel(unit);
        }
        if (loops_ran_out()) {
            atomicOr(status[0], kStatusLoopLimit);
        }
        return;
    }
    if (kLineArray != 0u) {
        uint first_cone = unit * kConesPerInvocation;
        if (first_cone < params.profile_columns) {
            uint end_cone = min(first_cone + kConesPerInvocation, params.profile_columns);
            gather_cone_columns(first_cone, end_cone);
            if (kSubpixel != 0u && band.row_end == params.rows) { // after the last band's pixels
                for (uint c = first_cone; c < end_cone; ++c) {
                    add_subpixel(c);
                }
            }
            if (loops_ran_out()) {
                atomicOr(status[0], kStatusLoopLimit);
            }
        }
        return;
    }
    uint column = unit;
    uint columns = params.columns;
    if (kGatherRows != 0u) { // every lane to the end (barriers)
        bool owned = column < columns;
        column_block_rows(column, owned);
        if (kSubpixel != 0u && owned) {
            add_subpixel(column);
        }
        if (loops_ran_out()) {
            atomicOr(status[0], kStatusLoopLimit);
        }
        return;
    }
    if (column >= columns) {
        return;
    }
    uint base = column * params.bins_padded;
    uint rows = params.rows;
    // A window of five rows of this column's echo (energy, range): two above, this one, two below
    // (range 0 = no hit or outside the image), from the band's first row.
    uint r0 = band.row_begin;
    vec2 up2 = r0 >= 2u ? load_echo((r0 - 2u) * columns + column) : vec2(0.0);
    vec2 up = r0 >= 1u ? load_echo((r0 - 1u) * columns + column) : vec2(0.0);
    vec2 er = r0 < rows ? load_echo(r0 * columns + column) : vec2(0.0);
    vec2 next = r0 + 1u < rows ? load_echo((r0 + 1u) * columns + column) : vec2(0.0);
    uvec2 view = view_columns_of(column);
    for (uint row = r0; row < band.row_end; ++row) {
        // the echo two rows down, loaded once: down2 here, down on the next row, er after that
        vec2 next2 = row + 2u < rows ? load_echo((row + 2u) * columns + column) : vec2(0.0);
        float e = er.x;
        if (e > 0.0) {
            // `precise` inside range_spread: the bin coordinates and shares round exactly as the CPU's.
            vec2 across = row_neighbour_ranges(row, column, view);
            RangeSpread spread = range_spread(kRangeKernel, up2, up, er, next, next2, across.x, across.y,
                                              params.range_min_m, params.inv_bin_width_m, params.edge_relative_jump,
                                              params.bins, params.absorption_per_bin);
            for (int k = first_lane_bin(spread.k_first); k <= spread.k_last; k += int(kBinLanes)) {
                precise float share = range_share(spread, k) * e;
                profiles[base + uint(k)] += share;
            }
        }
        up2 = up;
        up = er;
        er = next;
        next = next2;
    }
    if (kSubpixel != 0u && band.row_end == rows) { // after the last band's pixels
        add_subpixel(column);
    }
    if (loops_ran_out()) {
        atomicOr(status[0], kStatusLoopLimit);
    }
}
