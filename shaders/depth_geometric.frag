// Depth pass with the face-normal attachment (normal_method = geometric), fragment stage: the material
// id as depth.frag, plus the unit plane normal of this triangle in clip-linear coordinates
// (docs/pipeline.md §1). dFdx and dFdy of the interpolated q are both tangent to the triangle's plane
// (also in helper lanes outside it: the same plane, extended), so their cross is the plane normal.
// Its sign is arbitrary; the normals stage turns it to face the sonar.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"

layout(push_constant, std430) uniform DepthPushBlock {
    DepthPush draw;
};

layout(location = 0) in vec3 clip_linear;
layout(location = 0) out uint material_id;
layout(location = 1) out vec4 face_normal;

void main() {
    material_id = draw.material_id;
    vec3 n = cross(dFdx(clip_linear), dFdy(clip_linear));
    float len = length(n);
    face_normal = vec4(len > 0.0 ? n / len : vec3(0.0), 0.0);
}
