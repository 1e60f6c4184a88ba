#version 430
// Rasterise a mesh in its texture space: every texel a triangle covers receives the interpolated
// world position, normal and tangent there (texture baking). v grows downwards (glTF), so v = 0
// lands on the image's first row once the framebuffer is read top row first.
in vec2 in_uv;
in vec3 in_position;
in vec3 in_normal;
in vec4 in_tangent;
out vec3 v_position;
out vec3 v_normal;
out vec4 v_tangent;
void main() {
    v_position = in_position;
    v_normal = in_normal;
    v_tangent = in_tangent;
    gl_Position = vec4(in_uv.x * 2.0 - 1.0, in_uv.y * 2.0 - 1.0, 0.0, 1.0);
}
