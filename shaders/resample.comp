// Stage 4b, azimuth resampling of column profiles to beam centres (docs/pipeline.md §4):
// B(bin k, beam j) = sum over c in [begin_j, end_j) of w(c, j) * profile(bin k, column c).
// An invocation owns four consecutive range bins (one vec4 of the bin-fastest profiles) and a
// workgroup a run of kBeamsPerInvocation beams, so the beam-table loads are uniform (one scalar load
// for the group) and every profile load brings four bins. On a CPU device each non-uniform load is a
// scalar load per lane: four bins per load is what makes this pass cheap there.
//
// Output: beam-major B[j * bins_padded + k] (vec4 stores) when the side-lobe pass follows, else the
// public range-major B[k * beams + j], which is then the polar scan itself.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"

layout(local_size_x = kWorkgroupSize) in;
layout(constant_id = 1) const uint kBeamsPerInvocation = 16u; // set by the host
layout(constant_id = 2) const uint kBeamMajorOut = 1u;        // set by the host: the side-lobe pass follows

layout(std140, binding = 0) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = 5) readonly buffer ProfileBuffer { vec4 profiles4[]; };
layout(std430, binding = 6) writeonly buffer BeamProfileBuffer { float beam_profiles[]; };
layout(std430, binding = 10) readonly buffer ColumnBeamBuffer { uint column_beam[]; };
layout(std430, binding = 11) readonly buffer ColumnWeightBuffer { float column_weight[]; };
layout(std430, binding = 12) readonly buffer BeamBeginBuffer { uint beam_column_begin[]; };
layout(std430, binding = 13) readonly buffer BeamEndBuffer { uint beam_column_end[]; };

void main() {
    uint bins = params.bins;
    uint beams = params.beams;
    uint columns = params.columns;
    uint quads = params.bins_padded / 4u; // vec4s per column
    uint q = gl_GlobalInvocationID.x;
    uint first_beam = gl_WorkGroupID.y * kBeamsPerInvocation;
    if (q >= quads || first_beam >= beams) {
        return;
    }
    uint last_beam = min(first_beam + kBeamsPerInvocation, beams);
    for (uint j = first_beam; j < last_beam; ++j) {
        vec4 sum = vec4(0.0);
        uint end = min(beam_column_end[j], columns);
        for (uint c = beam_column_begin[j]; c < end; ++c) {
            uint beam = column_beam[c];
            // on a full circle the last beam's right neighbour is beam 0 (the seam columns)
            bool next = params.circular != 0u ? (beam + 1u) % beams == j : beam + 1u == j;
            float w = beam == j ? column_weight[c] : (next ? 1.0 - column_weight[c] : 0.0);
            sum += w * profiles4[c * quads + q];
        }
        uint k = 4u * q;
        if (kBeamMajorOut != 0u) {
            uint o = j * params.bins_padded + k;
            beam_profiles[o] = sum.x;
            beam_profiles[o + 1u] = sum.y;
            beam_profiles[o + 2u] = sum.z;
            beam_profiles[o + 3u] = sum.w;
        } else {
            for (uint i = 0u; i < 4u && k + i < bins; ++i) {
                beam_profiles[(k + i) * beams + j] = sum[i];
            }
        }
    }
}
