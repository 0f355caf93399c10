// Stage 3, echo (docs/pipeline.md §3): per pixel, slant range and the combined sonar equation.
// Each invocation handles a run of kPixelsPerInvocation consecutive pixels. Output echo2[p] = (energy relative to SL, slant range m).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"
#define REAL float
#define VKS_ATAN2 atan
#include "sonar_math.h"

layout(local_size_x = kWorkgroupSize) in;
layout(constant_id = 0) const uint kEffectFlags = 0u;
layout(constant_id = 1) const uint kPixelsPerInvocation = 4u; // set by the host
const bool kIncidence = (kEffectFlags & kEffectIncidence) != 0u;
const bool kVerticalPattern = (kEffectFlags & kEffectVerticalPattern) != 0u;
const bool kSpreading = (kEffectFlags & kEffectSpreading) != 0u;
const bool kAbsorption = (kEffectFlags & kEffectAbsorption) != 0u;

layout(std140, binding = 0) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = 1) readonly buffer DepthBuffer { float depth[]; };
layout(std430, binding = 2) readonly buffer MaterialIdBuffer { uint material_id[]; };
layout(std430, binding = 3) readonly buffer NormalsBuffer { vec4 normals4[]; };
layout(std430, binding = 4) writeonly buffer EchoBuffer { vec2 echo2[]; };
// The same buffer with accuracy.intermediates = fp16: (energy * echo_scale, range) as two halves.
layout(std430, binding = 4) writeonly buffer EchoHalfBuffer { uint echo_half2[]; };

void store_echo(uint p, vec2 energy_range) {
    if (params.echo_half != 0u) {
        echo_half2[p] = packHalf2x16(vec2(energy_range.x * params.echo_scale, energy_range.y));
    } else {
        echo2[p] = energy_range;
    }
}
layout(std430, binding = 9) readonly buffer MaterialBuffer { MaterialGpu materials[]; };

void echo_pixel(uint p) {
    float d = depth[p];
    if (!(d > 0.0)) {
        store_echo(p, vec2(0.0));
        return;
    }
    uint row = p / params.columns;
    uint column = p - row * params.columns;
    float u = pixel_coord(column % params.slice_columns, params.slice_columns, params.tan_half_h);
    float v = pixel_coord(row, params.rows, params.tan_half_v);
    float z = view_z_from_depth(d, params.depth_a, params.depth_b);
    float r = slant_range(z, u, v);
    uint m = material_id[p];
    if (r < params.range_min_m || r >= params.range_max_m || m >= uint(materials.length())) {
        store_echo(p, vec2(0.0, r)); // kNoMaterial is >= any material count
        return;
    }
    float scatter = 1.0;
    if (kIncidence && materials[m].model == kScatterLambert) {
        scatter = normals4[p].w;
    }
    float omega = pixel_solid_angle(u, v, 2.0 * params.tan_half_h / float(params.slice_columns),
                                    2.0 * params.tan_half_v / float(params.rows));
    float vertical = 1.0;
    if (kVerticalPattern) {
        vertical = pattern_power(params.vpattern_shape, params.vpattern_k, params.vpattern_halfwidth_rad,
                                 pixel_elevation(u, v));
    }
    float e = echo_energy(materials[m].backscatter_linear, scatter, omega, r, params.alpha_db_per_m, vertical,
                          kSpreading, kAbsorption);
    store_echo(p, vec2(e, r));
}

void main() {
    uint pixels = params.columns * params.rows;
    uint first = gl_GlobalInvocationID.x * kPixelsPerInvocation;
    uint last = min(first + kPixelsPerInvocation, pixels);
    for (uint p = first; p < last; ++p) {
        echo_pixel(p);
    }
}
