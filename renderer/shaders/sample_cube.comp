#version 430
// Read a cube map at arbitrary directions and mip levels (tests, probes, debugging).
layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer Queries { vec4 queries[]; };  // xyz direction, w lod
layout(std430, binding = 1) writeonly buffer Results { vec4 results[]; };
uniform samplerCube u_cube;
uniform int u_count;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= uint(u_count)) return;
    results[i] = textureLod(u_cube, queries[i].xyz, queries[i].w);
}
