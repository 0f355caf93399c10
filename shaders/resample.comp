// Stage 4b, azimuth resampling of column profiles to beam centres (docs/pipeline.md §4):
// B(bin k, beam j) = sum over c in [begin_j, end_j) of w(c, j) * profile(bin k, column c).
// An invocation owns four consecutive range bins (one vec4 of the bin-fastest profiles) and a
// workgroup a run of kBeamsPerInvocation beams, so the beam-table loads are uniform (one scalar load
// for the group) and every profile load brings four bins. On a CPU device each non-uniform load is a
// scalar load per lane: four bins per load is what makes this pass cheap there.
//
// Output: beam-major B[j * bins_padded + k] (vec4 stores) when the side-lobe pass follows (then only read
// back, as Frame::beam_profiles: the side-lobe passes read the profile columns), else the public
// range-major B[k * beams + j], which is then the polar scan itself.
//
// Two ways to walk the columns, the same sums in the same order (src/vk/resample_walk.cpp):
// - gather: each beam sums its own span of columns, so a column that feeds two beams is loaded twice;
// - walk (where the host found that every run's columns feed its beams in order, as they do on any
//   fan short of a full circle): the run's columns are loaded once, each adding its weight to its
//   beam's sum and its 1 - weight to a running sum that starts the next beam. On lavapipe a storage
//   load is a loop over the lanes; halving the loads made beamform ~0.3 ms faster on 2 cores
//   (docs/benchmarks.md).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"
#define REAL float
#define VKS_ATAN2 atan
#include "sonar_math.h"

layout(local_size_x = kWorkgroupSize) in;
layout(constant_id = kSpecPerInvocation) const uint kBeamsPerInvocation = 16u; // set by the host
layout(constant_id = kSpecBeamMajorOut) const uint kBeamMajorOutFlag = 1u; // the side-lobe pass follows
layout(constant_id = kSpecResampleWalk) const uint kWalkFlag = 0u;          // walk the run's columns once (see above)
const bool kBeamMajorOut = kBeamMajorOutFlag != 0u;
const bool kWalk = kWalkFlag != 0u;

layout(std140, binding = kBindingParams) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = kBindingProfiles) readonly buffer ProfileBuffer { vec4 profiles4[]; };
layout(std430, binding = kBindingBeamProfiles) writeonly buffer BeamProfileBuffer { float beam_profiles[]; };
layout(std430, binding = kBindingBeamProfiles) writeonly buffer BeamProfileBuffer4 { vec4 beam_profiles4[]; }; // beam-major out
// Per pixel column (beam, weight bits): the column's tent weight goes to `beam`, 1 - weight to the next.
layout(std430, binding = kBindingColumnTable) readonly buffer ColumnTable { uvec2 column_entry[]; };
// Per beam (first column, end column) of the columns that reach it.
layout(std430, binding = kBindingBeamTable) readonly buffer BeamTable { uvec2 beam_entry[]; };
// The same tables as uniform blocks where both fit (src/vk/pipelines.h), two entries per uvec4. The
// beam index is the same for every lane of a workgroup: one scalar load on lavapipe, where a storage
// load is a loop over the lanes.
layout(constant_id = kSpecUniformTables) const uint kUniformTables = 0u;
layout(constant_id = kSpecTableVec4s0) const uint kColumnVec4s = 1u;
layout(constant_id = kSpecTableVec4s1) const uint kBeamVec4s = 1u;
layout(std140, binding = kBindingColumnTableUniform) uniform ColumnBlock { uvec4 column_entry4[kColumnVec4s]; };
layout(std140, binding = kBindingBeamTableUniform) uniform BeamBlock { uvec4 beam_entry4[kBeamVec4s]; };

uvec2 column_at(uint c) {
    if (kUniformTables != 0u) {
        uvec4 pair = column_entry4[c >> 1u];
        return (c & 1u) == 0u ? pair.xy : pair.zw;
    }
    return column_entry[c];
}
uvec2 beam_at(uint j) {
    if (kUniformTables != 0u) {
        uvec4 pair = beam_entry4[j >> 1u];
        return (j & 1u) == 0u ? pair.xy : pair.zw;
    }
    return beam_entry[j];
}

void store_beam(uint j, uint q, vec4 sum) {
    if (kBeamMajorOut) {
        // one vec4 store: lavapipe loops over the lanes once per store, not per component
        beam_profiles4[j * (params.bins_padded / 4u) + q] = sum;
    } else {
        uint k = 4u * q;
        for (uint i = 0u; i < 4u && k + i < params.bins; ++i) {
            beam_profiles[(k + i) * params.beams + j] = sum[i];
        }
    }
}

// Beam j's share of column c: w(c, j) of docs/pipeline.md §4.
float gather_weight(uvec2 entry, uint j) {
    uint share = resample_share(entry.x, j, params.beams, params.circular != 0u);
    float column_weight = uintBitsToFloat(entry.y);
    return share == 1u ? column_weight : (share == 2u ? 1.0 - column_weight : 0.0);
}

void gather(uint q, uint first_beam, uint last_beam) {
    uint columns = params.profile_columns;
    uint quads = params.bins_padded / 4u;
    for (uint j = first_beam; j < last_beam; ++j) {
        precise vec4 sum = vec4(0.0); // no fused multiply-add: the CPU rounds each product
        uvec2 span = beam_at(j);
        uint end = min(span.y, columns);
        for (uint c = span.x; c < end; ++c) {
            sum += gather_weight(column_at(c), j) * profiles4[c * quads + q];
        }
        store_beam(j, q, sum);
    }
}

// The host checked that beam j's span is the columns of beam j - 1 (first beam of the run only:
// later ones were walked already, their 1 - weight shares are in `carry`) and then its own, up to
// its end. So each beam adds the same terms in the same order as gather().
void walk(uint q, uint first_beam, uint last_beam) {
    uint columns = params.profile_columns;
    uint quads = params.bins_padded / 4u;
    uint c = beam_at(first_beam).x;
    precise vec4 carry = vec4(0.0);
    for (uint j = first_beam; j < last_beam; ++j) {
        precise vec4 sum = carry;
        carry = vec4(0.0);
        uint end = min(beam_at(j).y, columns);
        for (; c < end; ++c) {
            uvec2 entry = column_at(c);
            float column_weight = uintBitsToFloat(entry.y);
            bool own = entry.x == j;
            vec4 profile = profiles4[c * quads + q];
            sum += (own ? column_weight : 1.0 - column_weight) * profile;
            if (own) {
                carry += (1.0 - column_weight) * profile;
            }
        }
        store_beam(j, q, sum);
    }
}

void main() {
    uint quads = params.bins_padded / 4u; // vec4s per column
    uint q = gl_GlobalInvocationID.x;
    uint first_beam = gl_WorkGroupID.y * kBeamsPerInvocation;
    if (q >= quads || first_beam >= params.beams) {
        return;
    }
    uint last_beam = min(first_beam + kBeamsPerInvocation, params.beams);
    if (kWalk) {
        walk(q, first_beam, last_beam);
    } else {
        gather(q, first_beam, last_beam);
    }
}
