// Stage 4b, azimuth resampling of column profiles to beam centres (docs/pipeline.md §4):
// B(bin k, beam j) = sum over c in [begin_j, end_j) of w(c, j) * profile(bin k, column c).
// Invocations are consecutive range bins and a workgroup owns a run of kBeamsPerInvocation beams, so
// the beam-table loads are uniform (one scalar load for the group) and the profile loads, from the
// column-major GPU layout profiles[c * bins + k], are contiguous across invocations.
// Output: the public range-major layout B[k * beams + j] (the polar scan itself without side lobes).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"

layout(local_size_x = kWorkgroupSize) in;
layout(constant_id = 1) const uint kBeamsPerInvocation = 16u; // set by the host

layout(std140, binding = 0) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = 5) readonly buffer ProfileBuffer { float profiles[]; };
layout(std430, binding = 6) writeonly buffer BeamProfileBuffer { float beam_profiles[]; };
layout(std430, binding = 10) readonly buffer ColumnBeamBuffer { uint column_beam[]; };
layout(std430, binding = 11) readonly buffer ColumnWeightBuffer { float column_weight[]; };
layout(std430, binding = 12) readonly buffer BeamBeginBuffer { uint beam_column_begin[]; };
layout(std430, binding = 13) readonly buffer BeamEndBuffer { uint beam_column_end[]; };

void main() {
    uint bins = params.bins;
    uint beams = params.beams;
    uint columns = params.columns;
    uint k = gl_GlobalInvocationID.x;
    uint first_beam = gl_WorkGroupID.y * kBeamsPerInvocation;
    if (k >= bins || first_beam >= beams) {
        return;
    }
    uint last_beam = min(first_beam + kBeamsPerInvocation, beams);
    for (uint j = first_beam; j < last_beam; ++j) {
        float sum = 0.0;
        uint end = min(beam_column_end[j], columns);
        for (uint c = beam_column_begin[j]; c < end; ++c) {
            uint beam = column_beam[c];
            float w = beam == j ? column_weight[c] : (beam + 1u == j ? 1.0 - column_weight[c] : 0.0);
            sum += w * profiles[c * bins + k];
        }
        beam_profiles[k * beams + j] = sum;
    }
}
