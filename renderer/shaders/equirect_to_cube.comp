#version 430
#include "common.glsl"
// Resample an equirectangular HDR into one cube-map level.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
layout(rgba16f, binding = 0) uniform writeonly imageCube u_cube;
uniform sampler2D u_equirect;
uniform int u_size;
// Supersampling: each cube texel averages s x s equirect lookups so that a cube smaller than the
// panorama does not alias (a sun a few texels wide must keep its energy).
uniform int u_supersample;

void main() {
    ivec3 id = ivec3(gl_GlobalInvocationID);
    if (id.x >= u_size || id.y >= u_size) return;
    vec3 sum = vec3(0.0);
    float wsum = 0.0;
    for (int j = 0; j < u_supersample; ++j) {
        for (int i = 0; i < u_supersample; ++i) {
            vec2 sub = (vec2(id.xy) + (vec2(i, j) + 0.5) / float(u_supersample)) / float(u_size) * 2.0 - 1.0;
            vec3 d = cube_face_direction(id.z, sub);
            // Weight by the sub-sample's solid angle so the texel holds the mean radiance.
            vec2 st = sub;
            float w = pow(1.0 + dot(st, st), -1.5);
            sum += w * textureLod(u_equirect, direction_to_equirect_uv(d), 0.0).rgb;
            wsum += w;
        }
    }
    imageStore(u_cube, id, vec4(sum / wsum, 1.0));
}
