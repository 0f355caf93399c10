// Stage 4c, horizontal beam pattern / side lobes (docs/pipeline.md §4): convolution along beams,
// polar[k * beams + j] = sum_t sidelobe_weight[j * taps + t] * B[k * beams + j - K + t].
// Runs only when the horizontal-pattern effect is on.
//
// A workgroup owns a run of kBeamsPerInvocation beams (the same for all its invocations, so the
// weight loads are uniform) and each invocation one range bin of it. The invocation walks the source
// beams of the run once, in increasing order, and adds each to every output it reaches: every B value
// is loaded once per run instead of once per tap, and each output still sums its taps in increasing t.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"

layout(local_size_x = kWorkgroupSize) in;
layout(constant_id = 1) const uint kBeamsPerInvocation = 16u; // set by the host, at most kMaxRun
const uint kMaxRun = 32u;

layout(std140, binding = 0) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = 6) readonly buffer BeamProfileBuffer { float beam_profiles[]; };
layout(std430, binding = 7) writeonly buffer PolarBuffer { float polar[]; };
layout(std430, binding = 14) readonly buffer SidelobeBuffer { float sidelobe_weight[]; };

void main() {
    uint bins = params.bins;
    uint beams = params.beams;
    uint taps = params.sidelobe_taps;
    int half_taps = int(taps - 1u) / 2;
    uint k = gl_WorkGroupID.y * kWorkgroupSize + gl_LocalInvocationID.x;
    uint first_beam = gl_WorkGroupID.x * kBeamsPerInvocation;
    if (k >= bins || first_beam >= beams) {
        return;
    }
    uint run = min(min(kBeamsPerInvocation, kMaxRun), beams - first_beam);
    float sums[kMaxRun];
    for (uint r = 0u; r < run; ++r) {
        sums[r] = 0.0;
    }
    uint row = k * beams;
    int first_source = max(int(first_beam) - half_taps, 0);
    int last_source = min(int(first_beam + run) - 1 + half_taps, int(beams) - 1);
    for (int source = first_source; source <= last_source; ++source) {
        float b = beam_profiles[row + uint(source)];
        for (uint r = 0u; r < run; ++r) {
            int t = source - int(first_beam + r) + half_taps;
            if (t >= 0 && t < int(taps)) {
                sums[r] += sidelobe_weight[(first_beam + r) * taps + uint(t)] * b;
            }
        }
    }
    for (uint r = 0u; r < run; ++r) {
        polar[row + first_beam + r] = sums[r];
    }
}
