#version 430
#include "common.glsl"
#include "brdf.glsl"
// GGX-prefiltered radiance for one roughness level of the split-sum approximation (N = V = R),
// by filtered importance sampling (Krivanek & Colbert): each sample reads a source mip whose texel
// solid angle matches the sample's share of the lobe, which removes the fireflies of bright suns.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
layout(rgba16f, binding = 0) uniform writeonly imageCube u_out;
uniform samplerCube u_source;      // environment cube with a full mip chain
uniform int u_size;                // size of the level being written
uniform int u_source_size;         // base size of u_source
uniform float u_roughness;         // perceptual roughness of this level
uniform int u_samples;

void main() {
    ivec3 id = ivec3(gl_GlobalInvocationID);
    if (id.x >= u_size || id.y >= u_size) return;
    vec3 n = cube_texel_direction(id.z, id.xy, u_size);
    float alpha = u_roughness * u_roughness;
    mat3 frame = basis_around(n);
    float texel_solid_angle = 4.0 * PI / (6.0 * float(u_source_size * u_source_size));
    float max_lod = log2(float(u_source_size));
    vec3 sum = vec3(0.0);
    float wsum = 0.0;
    for (int i = 0; i < u_samples; ++i) {
        vec3 h = frame * ggx_sample_half_vector(hammersley(uint(i), uint(u_samples)), alpha);
        vec3 l = reflect(-n, h);
        float n_dot_l = dot(n, l);
        if (n_dot_l <= 0.0) continue;
        float n_dot_h = max(dot(n, h), 0.0);
        // pdf of l = D * (N.H) / (4 V.H) with V = N, so V.H = N.H.
        float pdf = ggx_distribution(n_dot_h, alpha) * 0.25;
        float sample_solid_angle = 1.0 / (float(u_samples) * pdf + 1e-6);
        float lod = alpha == 0.0 ? 0.0 : clamp(0.5 * log2(sample_solid_angle / texel_solid_angle) + 1.0, 0.0, max_lod);
        sum += textureLod(u_source, l, lod).rgb * n_dot_l;
        wsum += n_dot_l;
    }
    imageStore(u_out, id, vec4(sum / max(wsum, 1e-6), 1.0));
}
