// Embedding: a host engine's depth image -> vksonar's depth and material buffers (docs/embedding.md).
// One invocation per pixel; the host image's pixel grid is the plan's (core/host_plan.cpp), so pixel p
// reads texel (column, row) as is. Output follows the depth pass's contract (docs/pipeline.md §1):
// reversed-Z d = depth_a / z + depth_b in (0, 1], 0 = no hit; material 0 (the config's default
// backscatter) where hit, kNoMaterial elsewhere.
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_samplerless_texture_functions : require
#include "sonar_shared.h"
#include "host_depth_shared.h"

layout(local_size_x = kWorkgroupSize) in;

layout(std140, set = 0, binding = kBindingParams) uniform ParamsBlock { SonarParams params; };
layout(std430, set = 0, binding = kBindingDepth) writeonly buffer DepthBuffer { float depth[]; };
layout(std430, set = 0, binding = kBindingMaterialId) writeonly buffer MaterialBuffer { uint material_id[]; };
layout(set = 1, binding = kBindingHostDepthImage) uniform texture2D host_depth;
layout(push_constant) uniform PushBlock { ImportDepthPush push; };

void main() {
    uint p = gl_GlobalInvocationID.x;
    uint columns = params.columns;
    if (p >= columns * params.rows) {
        return;
    }
    float d = texelFetch(host_depth, ivec2(int(p % columns), int(p / columns)), 0).r;
    // Each test is written so that NaN fails it: a NaN texel is no hit.
    bool hit;
    float z;
    if (push.encoding == kHostDepthLinear) {
        hit = d > 0.0 && !isinf(d);
        z = d;
    } else {
        hit = push.encoding == kHostDepthReversed ? d > 0.0 : d < 1.0;
        z = push.near_m / (push.z_a + push.z_b * d);
    }
    float out_depth = 0.0;
    if (hit && z > 0.0 && !isinf(z)) {
        // Beyond far (the range gate's far edge) this is <= 0: no hit, as the depth pass's far plane
        // would clip it. Nearer than the near plane it exceeds 1; clamped, the pixel lies at near, short
        // of the gate, so the echo stage gives it no energy (the depth pass would have clipped it instead).
        out_depth = min(params.depth_a / z + params.depth_b, 1.0);
    }
    out_depth = max(out_depth, 0.0);
    depth[p] = out_depth;
    material_id[p] = out_depth > 0.0 ? 0u : kNoMaterial;
}
