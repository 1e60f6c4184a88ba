#version 430
#include "common.glsl"
// Gather the texels of one (small) level of the environment cube with their directions and
// solid angles, so the convolution below is an exact Riemann sum over the sphere.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
struct Source { vec4 direction_solid_angle; vec4 radiance; };
layout(std430, binding = 0) writeonly buffer Sources { Source sources[]; };
uniform samplerCube u_source;
uniform int u_size;   // size of the level read
uniform float u_lod;  // its mip level in u_source

void main() {
    ivec3 id = ivec3(gl_GlobalInvocationID);
    if (id.x >= u_size || id.y >= u_size) return;
    vec3 d = cube_texel_direction(id.z, id.xy, u_size);
    uint index = uint((id.z * u_size + id.y) * u_size + id.x);
    sources[index].direction_solid_angle = vec4(d, cube_texel_solid_angle(id.xy, u_size));
    sources[index].radiance = vec4(textureLod(u_source, d, u_lod).rgb, 0.0);
}
