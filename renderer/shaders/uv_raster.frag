#version 430
in vec3 v_position;
in vec3 v_normal;
in vec4 v_tangent;
layout(location = 0) out vec4 out_position;  // xyz, w = 1 where covered
layout(location = 1) out vec4 out_normal;
layout(location = 2) out vec4 out_tangent;
void main() {
    out_position = vec4(v_position, 1.0);
    out_normal = vec4(normalize(v_normal), 0.0);
    out_tangent = vec4(normalize(v_tangent.xyz), v_tangent.w);
}
