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
        float r = er.y;
        if (e > 0.0) {
            // `precise`: no fused multiply-add here, so that the bin coordinates and every share are
            // rounded exactly as the CPU reference rounds them (a GPU compiler may otherwise contract
            // a*b+c, and an ulp of a bin coordinate moves energy between bins).
            precise float x = range_bin_coord(r, params.range_min_m, params.inv_bin_width_m);
            int nb = int(bins);
            if (kRangeKernel == kRangeKernelFootprint) {
                float jump = params.edge_relative_jump;
                float inv_bw = params.inv_bin_width_m;
                float a = footprint_edge_offset(up.y, up2.y, r, next.y, jump);
                float b = footprint_edge_offset(next.y, next2.y, r, up.y, jump);
                precise float xl = x + footprint_lo(a, b) * inv_bw;
                precise float xh = x + footprint_hi(a, b) * inv_bw;
                precise float centre = 0.5 * (xl + xh);
                float width = min(max(xh - xl, 1.0), kMaxFootprintBins);
                precise float lo = centre - 0.5 * width;
                precise float hi = centre + 0.5 * width;
                // the density's slope from the neighbours' footprints (both on this surface)
                float g = 0.0;
                if (a != 0.0 && b != 0.0 && up2.y > 0.0 && next2.y > 0.0) {
                    precise float w_up = 0.5 * abs(up2.y - r) * inv_bw;
                    precise float w_down = 0.5 * abs(r - next2.y) * inv_bw;
                    // between the neighbours' footprint centres, (r + 2 r_q + r_q2) / 4 on either side
                    precise float span = (2.0 * (up.y - next.y) + (up2.y - next2.y)) * (0.25 * inv_bw);
                    g = footprint_log_slope(up.x, w_up, next.x, w_down, span, width);
                }
                float inv_norm = 1.0 / (width * sinhc_of(0.5 * g * width));
                // only the bins of the window: the rest of the footprint is gated away
                int k_first = max(int(floor(lo)), 0);
                int k_last = min(int(floor(hi)), nb - 1);
                for (int k = k_first; k <= k_last; ++k) {
                    precise float share = footprint_share(lo, hi, centre, g, inv_norm, k) * e;
                    profiles[base + uint(k)] += share;
                }
            } else if (kRangeKernel == kRangeKernelTent) {
                precise float t = x - 0.5;
                float k0f = floor(t);
                precise float w1 = t - k0f;
                // a share outside the window is gated away
                int k0 = int(clamp(k0f, -2.0, float(bins)));
                precise float share0 = (1.0 - w1) * e;
                precise float share1 = w1 * e;
                if (k0 >= 0 && k0 < nb) {
                    profiles[base + uint(k0)] += share0;
                }
                if (k0 + 1 >= 0 && k0 + 1 < nb) {
                    profiles[base + uint(k0 + 1)] += share1;
                }
            } else {
                float kf = floor(x);
                if (kf >= 0.0 && kf < float(bins)) {
                    profiles[base + uint(kf)] += e;
                }
            }
        }
        up2 = up;
        up = er;
        er = next;
        next = next2;
    }
}
