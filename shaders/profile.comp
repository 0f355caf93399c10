// Stage 4a, per-column range profiles (docs/pipeline.md §4). One invocation owns one pixel column and
// walks its rows top to bottom, so every profile cell has exactly one writer and a fixed summation
// order: no atomics, bit-identical run to run. The host zeroes `profiles` (vkCmdFillBuffer) first:
// a memset is far cheaper than per-invocation strided stores.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"
#define REAL float
#define VKS_ATAN2 atan
#include "sonar_math.h"

layout(local_size_x = kWorkgroupSize) in;

layout(std140, binding = 0) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = 4) readonly buffer EchoBuffer { vec2 echo2[]; };
layout(std430, binding = 5) buffer ProfileBuffer { float profiles[]; };

void main() {
    uint column = gl_GlobalInvocationID.x;
    uint columns = params.columns;
    if (column >= columns) {
        return;
    }
    uint bins = params.bins;
    bool tent = params.range_kernel == kRangeKernelTent;
    for (uint row = 0u; row < params.rows; ++row) {
        vec2 er = echo2[row * columns + column];
        float e = er.x;
        if (!(e > 0.0)) {
            continue;
        }
        float x = range_bin_coord(er.y, params.range_min_m, params.bin_width_m);
        if (tent) {
            float t = x - 0.5;
            float k0f = floor(t);
            float w1 = t - k0f;
            // a share below bin 0 goes to bin 0, above the last bin to the last bin: energy is kept
            int k0 = int(clamp(k0f, -1.0, float(bins)));
            uint b0 = uint(clamp(k0, 0, int(bins) - 1));
            uint b1 = uint(clamp(k0 + 1, 0, int(bins) - 1));
            profiles[b0 * columns + column] += (1.0 - w1) * e;
            profiles[b1 * columns + column] += w1 * e;
        } else {
            float kf = floor(x);
            if (kf >= 0.0 && kf < float(bins)) {
                profiles[uint(kf) * columns + column] += e;
            }
        }
    }
}
