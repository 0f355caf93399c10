// Stage 4c, horizontal beam pattern / side lobes (docs/pipeline.md §4): the near kernel over the range
// profiles' columns, polar[k * beams + j] = sum_t weight[j * taps + t] * profile(bin k, column
// begin_j + t), taps in increasing t: each column weighted by the pattern at its own direction's
// separation from the beam (Plan::near_column_*). Runs only when the horizontal-pattern effect is on.
//
// An invocation owns four consecutive range bins (one vec4 of the bin-fastest profiles that
// profile.comp writes) and a workgroup a run of kBeamsPerInvocation beams, so the weight loads are
// uniform and each profile load brings four bins. The invocation walks the source columns of its run
// once, in increasing order, and adds each to every output whose columns hold it; each output still
// sums its taps in increasing t. The run length is a compile-time constant so the loop over the
// accumulators unrolls and they stay in registers.
//
// With the far side lobes (kFarSidelobes), each output then adds its beam's share of its two cells of
// far_sidelobe.comp's grid, which ran before: near + (share0 * cell0 + share1 * cell1), at least 0
// (far_scan_cell).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"
#define REAL float
#define VKS_ATAN2 atan
#include "sonar_math.h"
#include "sonar_kernels.h"

layout(local_size_x = kWorkgroupSize) in;
layout(constant_id = kSpecPerInvocation) const uint kBeamsPerInvocation = 16u; // set by the host, a multiple of 4
// 1 when beams % 4 == 0: four beams of a range bin go out as one vec4 store (lavapipe loops over the
// lanes once per store instruction, so 16 vec4 stores cost a quarter of 64 scalar ones).
layout(constant_id = kSpecVec4Out) const uint kVec4Out = 0u;
layout(constant_id = kSpecFarSidelobes) const uint kFarSidelobes = 0u; // 1: add far_sidelobe.comp's cells
// Focus bands (Plan::near_bands): more than 1, each bin reads its band's weights, one lane at a time.
layout(constant_id = kSpecNearBands) const uint kNearBands = 1u;

layout(std140, binding = kBindingParams) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = kBindingProfiles) readonly buffer ProfileBuffer { vec4 profiles4[]; };
layout(std430, binding = kBindingPolar) writeonly buffer PolarBuffer { float polar[]; };
layout(std430, binding = kBindingPolar) writeonly buffer PolarBuffer4 { vec4 polar4[]; };
layout(std430, binding = kBindingSidelobeWeight) readonly buffer SidelobeBuffer { float sidelobe_weight[]; };
layout(std430, binding = kBindingFarTable) readonly buffer FarTableBuffer { float far_table[]; };
layout(std430, binding = kBindingFarCells) readonly buffer FarCellsBuffer { vec4 far_cells4[]; };
// The same weights as a uniform block where they fit one (src/vk/pipelines.h). Every lane of a
// workgroup reads the same weight: one scalar load on lavapipe, a loop over the lanes from storage.
layout(constant_id = kSpecUniformTables) const uint kUniformTables = 0u;
layout(constant_id = kSpecTableVec4s0) const uint kWeightVec4s = 1u;
layout(std140, binding = kBindingSidelobeWeightUniform) uniform SidelobeBlock { vec4 sidelobe_weight4[kWeightVec4s]; };

layout(constant_id = kSpecTableVec4s1) const uint kFarTableVec4s = 1u;
layout(std140, binding = kBindingFarTableUniform) uniform FarTableBlock { vec4 far_table4[kFarTableVec4s]; };

float weight(uint i) {
    return kUniformTables != 0u ? sidelobe_weight4[i >> 2u][i & 3u] : sidelobe_weight[i];
}

float far_entry(uint i) {
    return kUniformTables != 0u ? far_table4[i >> 2u][i & 3u] : far_table[i];
}

void main() {
    uint bins = params.bins;
    int beams = int(params.beams);
    int taps = int(params.near_column_taps);
    int columns = int(params.profile_columns);
    uint quads = params.bins_padded / 4u;
    uint q = gl_GlobalInvocationID.x;
    int first_beam = int(gl_WorkGroupID.y * kBeamsPerInvocation);
    if (q >= quads || first_beam >= beams) {
        return;
    }
    precise vec4 sums[kBeamsPerInvocation]; // no fused multiply-add: the CPU rounds each product
    for (uint r = 0u; r < kBeamsPerInvocation; ++r) {
        sums[r] = vec4(0.0);
    }
    // The table (src/vk/vulkan_backend.cpp): the weights (every band's), then per run the first and last
    // source column any of its beams hears, then per beam its first column, then with focus bands each
    // bin's band (floats, exact below 2^24; unwrapped: on a full circle a column index wraps modulo the
    // columns).
    uint runs = (uint(beams) + kBeamsPerInvocation - 1u) / kBeamsPerInvocation;
    uint weights = kNearBands * uint(beams * taps);
    uint run_entry = weights + 2u * gl_WorkGroupID.y;
    uint begin_entry = weights + 2u * runs + uint(first_beam);
    uvec4 band_offset = uvec4(0u);
    if (kNearBands > 1u) {
        uint band_entry = weights + 2u * runs + uint(beams) + 4u * q;
        for (uint i = 0u; i < 4u; ++i) {
            band_offset[i] = uint(weight(band_entry + i)) * uint(beams * taps);
        }
    }
    int first_source = int(weight(run_entry));
    int last_source = int(weight(run_entry + 1u));
    int begin[kBeamsPerInvocation];
    for (uint r = 0u; r < kBeamsPerInvocation; ++r) {
        begin[r] = first_beam + int(r) < beams ? int(weight(begin_entry + r)) : 0;
    }
    for (int source = first_source; source <= last_source; ++source) {
        int wrapped = source < 0 ? source + columns : (source >= columns ? source - columns : source); // in (-columns, 2 columns)
        vec4 b = profiles4[uint(wrapped) * quads + q];
        for (uint r = 0u; r < kBeamsPerInvocation; ++r) {
            int j = first_beam + int(r);
            int t = source - begin[r];
            if (t >= 0 && t < taps && j < beams) {
                uint i = uint(j * taps + t);
                if (kNearBands > 1u) {
                    vec4 w = vec4(weight(band_offset.x + i), weight(band_offset.y + i), weight(band_offset.z + i),
                                  weight(band_offset.w + i));
                    sums[r] += w * b;
                } else {
                    sums[r] += weight(i) * b; // 0 past the beam's own columns: adds exactly +0
                }
            }
        }
    }
    if (kFarSidelobes != 0u) {
        for (uint r = 0u; r < kBeamsPerInvocation; ++r) {
            uint j = uint(first_beam) + r;
            if (j < uint(beams)) {
                uint i = 8u * j;
                vec4 cell = vec4(far_entry(i), far_entry(i + 1u), far_entry(i + 2u), far_entry(i + 3u));
                vec4 phase = vec4(far_entry(i + 4u), far_entry(i + 5u), far_entry(i + 6u), far_entry(i + 7u));
                uint c0 = uint(cell.x), c1 = uint(cell.y);
                float s0 = far_cell_share(cell, c0), s1 = far_cell_share(cell, c1);
                uint cells = params.far_cells;
                precise vec4 l[3] = vec4[3](vec4(0.0), vec4(0.0), vec4(0.0));
                for (uint m = 0u; m < params.far_channels; ++m) {
                    l[m] = s0 * far_cells4[(m * cells + c0) * quads + q] + s1 * far_cells4[(m * cells + c1) * quads + q];
                }
                for (uint b = 0u; b < 4u; ++b) {
                    sums[r][b] = far_scan_cell(sums[r][b], far_sidelobe_level(phase, l[0][b], l[1][b], l[2][b]));
                }
            }
        }
    }
    uint k = 4u * q;
    if (kVec4Out != 0u) {
        uint beam_quads = uint(beams) / 4u;
        for (uint r = 0u; r < kBeamsPerInvocation; r += 4u) {
            uint j = uint(first_beam) + r;
            for (uint i = 0u; i < 4u; ++i) {
                if (j < uint(beams) && k + i < bins) {
                    polar4[(k + i) * beam_quads + j / 4u] =
                        vec4(sums[r][i], sums[r + 1u][i], sums[r + 2u][i], sums[r + 3u][i]);
                }
            }
        }
        return;
    }
    for (uint r = 0u; r < kBeamsPerInvocation; ++r) {
        uint j = uint(first_beam) + r;
        for (uint i = 0u; i < 4u; ++i) {
            if (j < uint(beams) && k + i < bins) {
                polar[(k + i) * uint(beams) + j] = sums[r][i];
            }
        }
    }
}
