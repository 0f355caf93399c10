// Depth pass with the face-normal attachment (normal_method = geometric), vertex stage: depth.vert plus
// the clip-linear position q = (x_clip, y_clip, w_clip). q is an affine function of the local
// position, so its perspective-correct interpolation stays on the triangle's plane.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"

layout(push_constant, std430) uniform DepthPushBlock {
    DepthPush draw;
};

layout(location = 0) in vec3 position;
layout(location = 0) out vec3 clip_linear;

void main() {
    mat4 clip_from_local = mat4(
        vec4(draw.clip_from_local[0], draw.clip_from_local[1], draw.clip_from_local[2], draw.clip_from_local[3]),
        vec4(draw.clip_from_local[4], draw.clip_from_local[5], draw.clip_from_local[6], draw.clip_from_local[7]),
        vec4(draw.clip_from_local[8], draw.clip_from_local[9], draw.clip_from_local[10], draw.clip_from_local[11]),
        vec4(draw.clip_from_local[12], draw.clip_from_local[13], draw.clip_from_local[14], draw.clip_from_local[15]));
    gl_Position = clip_from_local * vec4(position, 1.0);
    clip_linear = gl_Position.xyw;
}
