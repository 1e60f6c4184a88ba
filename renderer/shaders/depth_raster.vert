#version 430
// Depth-only pass (next-view guidance): the camera-space z of each surface point, nothing else.
// One instance per camera: instance i draws into tile i of a grid of `u_columns` x `u_rows` tiles,
// clipped to its tile by the four clip distances (a triangle must not spill into its neighbours).
layout(std430, binding = 0) buffer Cameras {
    mat4 view_projection[];
};
layout(std430, binding = 1) buffer Eyes {
    vec4 position_forward[];  // per camera: position, then forward (OpenCV z axis), as vec4 pairs
};
uniform int u_columns;
uniform int u_rows;
in vec3 in_position;
out float v_depth;
void main() {
    int i = gl_InstanceID;
    vec3 eye = position_forward[2 * i].xyz;
    vec3 forward = position_forward[2 * i + 1].xyz;
    v_depth = dot(in_position - eye, forward);
    vec4 p = view_projection[i] * vec4(in_position, 1.0);
    gl_ClipDistance[0] = p.w - p.x;
    gl_ClipDistance[1] = p.w + p.x;
    gl_ClipDistance[2] = p.w - p.y;
    gl_ClipDistance[3] = p.w + p.y;
    float column = float(i % u_columns);
    float row = float(u_rows - 1 - i / u_columns);  // tile 0 at the top left; GL rows grow upwards
    gl_Position = vec4((p.x + p.w * (1.0 + 2.0 * column)) / float(u_columns) - p.w,
                       (p.y + p.w * (1.0 + 2.0 * row)) / float(u_rows) - p.w, p.z, p.w);
}
