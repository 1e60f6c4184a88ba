#version 430
#include "common.glsl"
#include "brdf.glsl"
// Split-sum BRDF table: for (N.V, perceptual roughness) the GGX-Smith directional albedo splits as
// F0 * A + B (Karis 2013). Texel centres map to N.V and roughness in (0, 1).
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
layout(rg32f, binding = 0) uniform writeonly image2D u_lut;
uniform int u_size;
uniform int u_samples;

void main() {
    ivec2 id = ivec2(gl_GlobalInvocationID.xy);
    if (id.x >= u_size || id.y >= u_size) return;
    float n_dot_v = (float(id.x) + 0.5) / float(u_size);
    float roughness = (float(id.y) + 0.5) / float(u_size);
    float alpha = roughness * roughness;
    vec3 v = vec3(sqrt(1.0 - n_dot_v * n_dot_v), 0.0, n_dot_v);
    float a = 0.0;
    float b = 0.0;
    for (int i = 0; i < u_samples; ++i) {
        vec3 h = ggx_sample_half_vector(hammersley(uint(i), uint(u_samples)), alpha);
        vec3 l = reflect(-v, h);
        float n_dot_l = l.z;
        float n_dot_h = max(h.z, 0.0);
        float v_dot_h = max(dot(v, h), 0.0);
        if (n_dot_l > 0.0) {
            // BRDF * cos / pdf with pdf = D N.H / (4 V.H): D cancels.
            float weight = smith_ggx_visibility(n_dot_v, n_dot_l, alpha) * n_dot_l * 4.0 * v_dot_h / n_dot_h;
            float fc = pow(1.0 - v_dot_h, 5.0);
            a += (1.0 - fc) * weight;
            b += fc * weight;
        }
    }
    imageStore(u_lut, id, vec4(a / float(u_samples), b / float(u_samples), 0.0, 0.0));
}
