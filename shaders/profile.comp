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

layout(local_size_x = kWorkgroupSize) in;

layout(constant_id = 2) const uint kRangeKernel = kRangeKernelFootprint; // params.range_kernel
layout(constant_id = 6) const uint kEchoHalf = 0u;                      // params.echo_half
// (constants, not uniforms: lavapipe would run the loads and stores of every kernel, src/vk/pipelines.h)

layout(std140, binding = 0) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = 4) readonly buffer EchoBuffer { vec2 echo2[]; };
layout(std430, binding = 4) readonly buffer EchoHalfBuffer { uint echo_half2[]; }; // accuracy.intermediates = fp16

vec2 load_echo(uint p) {
    if (kEchoHalf != 0u) {
        vec2 v = unpackHalf2x16(echo_half2[p]);
        return vec2(v.x / params.echo_scale, v.y);
    }
    return echo2[p];
}
layout(std430, binding = 5) buffer ProfileBuffer { float profiles[]; };

void main() {
    uint column = gl_GlobalInvocationID.x;
    uint columns = params.columns;
    if (column >= columns) {
        return;
    }
    uint bins = params.bins;
    uint base = column * params.bins_padded;
    uint rows = params.rows;
    float r_up = 0.0;
    vec2 er = load_echo(column);
    for (uint row = 0u; row < rows; ++row) {
        // the next row's echo, loaded once: r_down here, er on the next iteration
        vec2 next = row + 1u < rows ? load_echo((row + 1u) * columns + column) : vec2(0.0);
        float r_down = next.y;
        float e = er.x;
        float r = er.y;
        if (e > 0.0) {
            // `precise`: no fused multiply-add here, so that the bin coordinates and every share are
            // rounded exactly as the CPU reference rounds them (a GPU compiler may otherwise contract
            // a*b+c, and an ulp of a bin coordinate moves energy between bins).
            precise float x = range_bin_coord(r, params.range_min_m, params.inv_bin_width_m);
            if (kRangeKernel == kRangeKernelFootprint) {
                precise float extent = pixel_range_extent(r_up, r, r_down, params.edge_relative_jump) *
                                       params.inv_bin_width_m;
                float width = min(max(extent, 1.0), kMaxFootprintBins);
                precise float lo = x - 0.5 * width;
                precise float hi = x + 0.5 * width;
                float inv_width = 1.0 / width;
                int nb = int(bins);
                int k_first = int(floor(min(max(lo, 0.0), float(nb - 1))));
                int k_last = int(floor(min(max(hi, 0.0), float(nb - 1))));
                for (int k = k_first; k <= k_last; ++k) {
                    precise float share = footprint_share(lo, hi, inv_width, k, nb) * e;
                    profiles[base + uint(k)] += share;
                }
            } else if (kRangeKernel == kRangeKernelTent) {
                precise float t = x - 0.5;
                float k0f = floor(t);
                precise float w1 = t - k0f;
                // a share below bin 0 goes to bin 0, above the last bin to the last bin: energy is kept
                int k0 = int(clamp(k0f, -1.0, float(bins)));
                uint b0 = uint(clamp(k0, 0, int(bins) - 1));
                uint b1 = uint(clamp(k0 + 1, 0, int(bins) - 1));
                precise float share0 = (1.0 - w1) * e;
                precise float share1 = w1 * e;
                profiles[base + b0] += share0;
                profiles[base + b1] += share1;
            } else {
                float kf = floor(x);
                if (kf >= 0.0 && kf < float(bins)) {
                    profiles[base + uint(kf)] += e;
                }
            }
        }
        r_up = r;
        er = next;
    }
}
