// GGX microfacet BRDF pieces (alpha = perceptual_roughness^2, as glTF specifies).
// Mirrors renderer/brdf_reference.py, the numpy reference the tests integrate against.

// GGX half-vector sample in tangent space (z = normal) for a uniform pair xi.
vec3 ggx_sample_half_vector(vec2 xi, float alpha) {
    float a2 = alpha * alpha;
    float phi = 2.0 * PI * xi.x;
    float cos_theta = sqrt((1.0 - xi.y) / (1.0 + (a2 - 1.0) * xi.y));
    float sin_theta = sqrt(max(0.0, 1.0 - cos_theta * cos_theta));
    return vec3(sin_theta * cos(phi), sin_theta * sin(phi), cos_theta);
}

float ggx_distribution(float n_dot_h, float alpha) {
    float a2 = alpha * alpha;
    float f = n_dot_h * n_dot_h * (a2 - 1.0) + 1.0;
    return a2 / (PI * f * f);
}

// Height-correlated Smith visibility V = G2 / (4 N.L N.V).
float smith_ggx_visibility(float n_dot_v, float n_dot_l, float alpha) {
    float a2 = alpha * alpha;
    float gv = n_dot_l * sqrt(n_dot_v * n_dot_v * (1.0 - a2) + a2);
    float gl = n_dot_v * sqrt(n_dot_l * n_dot_l * (1.0 - a2) + a2);
    float denom = gv + gl;
    return denom > 0.0 ? 0.5 / denom : 0.0;
}
