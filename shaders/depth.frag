// Depth pass, fragment stage: the depth test (reversed-Z, GREATER) keeps the nearest surface; this
// writes its acoustic material id into the R32_UINT attachment (cleared to kNoMaterial).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"

layout(push_constant, std430) uniform DepthPushBlock {
    DepthPush draw;
};

layout(location = 0) out uint material_id;

void main() {
    material_id = draw.material_id;
}
