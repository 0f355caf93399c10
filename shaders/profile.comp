// Stage 4a, per-column range profiles (docs/pipeline.md §4). One invocation owns one pixel column and
// walks its rows top to bottom, so every profile cell has exactly one writer and a fixed summation
// order: no atomics, bit-identical run to run. The host zeroes `profiles` (vkCmdFillBuffer) first:
// a memset is far cheaper than per-invocation strided stores.
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
// (constants, not uniforms: lavapipe would run the loads and stores of every kernel, src/vk/pipelines.h)

layout(std140, binding = kBindingParams) uniform ParamsBlock { SonarParams params; };
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

void main() {
    uint column = gl_GlobalInvocationID.x;
    uint columns = params.columns;
    if (column >= columns) {
        return;
    }
    uint base = column * params.bins_padded;
    uint rows = params.rows;
    // A window of five rows of this column's echo (energy, range): two above, this one, two below
    // (range 0 = no hit or outside the image).
    vec2 up2 = vec2(0.0);
    vec2 up = vec2(0.0);
    vec2 er = load_echo(column);
    vec2 next = rows > 1u ? load_echo(columns + column) : vec2(0.0);
    for (uint row = 0u; row < rows; ++row) {
        // the echo two rows down, loaded once: down2 here, down on the next row, er after that
        vec2 next2 = row + 2u < rows ? load_echo((row + 2u) * columns + column) : vec2(0.0);
        float e = er.x;
        if (e > 0.0) {
            // `precise` inside range_spread: the bin coordinates and shares round exactly as the CPU's.
            RangeSpread spread = range_spread(kRangeKernel, up2, up, er, next, next2, params.range_min_m,
                                              params.inv_bin_width_m, params.edge_relative_jump, params.bins);
            for (int k = spread.k_first; k <= spread.k_last; ++k) {
                precise float share = range_share(spread, k) * e;
                profiles[base + uint(k)] += share;
            }
        }
        up2 = up;
        up = er;
        er = next;
        next = next2;
    }
}
