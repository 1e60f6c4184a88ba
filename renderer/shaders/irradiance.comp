#version 430
#include "common.glsl"
// Diffuse irradiance cube from the binned panorama (ibl.irradiance_sources): E(n) / pi = (1/pi) * sum_j L_j max(0, n . d_j) dOmega_j, stored in
// radiance units so that a white Lambertian surface reflects exactly this value.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
struct Source { vec4 direction_solid_angle; vec4 radiance; };
layout(std430, binding = 0) readonly buffer Sources { Source sources[]; };
layout(rgba16f, binding = 0) uniform writeonly imageCube u_out;
uniform int u_size;
uniform int u_source_count;

void main() {
    ivec3 id = ivec3(gl_GlobalInvocationID);
    if (id.x >= u_size || id.y >= u_size) return;
    vec3 n = cube_texel_direction(id.z, id.xy, u_size);
    vec3 sum = vec3(0.0);
    for (int j = 0; j < u_source_count; ++j) {
        vec4 ds = sources[j].direction_solid_angle;
        sum += sources[j].radiance.rgb * (max(dot(n, ds.xyz), 0.0) * ds.w);
    }
    imageStore(u_out, id, vec4(sum / PI, 1.0));
}
