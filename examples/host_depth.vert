// The example host engine's depth-only vertex shader: one clip_from_local matrix per draw.
#version 450
layout(push_constant) uniform DrawPush { mat4 clip_from_local; } draw;
layout(location = 0) in vec3 position;
void main() {
    gl_Position = draw.clip_from_local * vec4(position, 1.0);
}
