#version 430
// Resolves a k x k supersampled G-buffer to the output size on the GPU (the numpy reference is
// pbr_renderer.downsample_reference): the beauty and the radiance are plain box means; the G-buffer
// channels are means over covered sub-pixels only (0 where none is covered), the normal renormalised;
// the coverage is the covered fraction. Reading back k^2 fewer texels, and not averaging them in numpy,
// is what makes supersampled renders (the training data) fast.
layout(location = 0) out vec4 o_radiance;
layout(location = 1) out vec4 o_albedo;      // a = coverage
layout(location = 2) out vec4 o_material;
layout(location = 3) out vec4 o_normal_depth;
layout(location = 4) out vec4 o_uv;
layout(location = 5) out vec4 o_beauty;      // the tone-mapped display image, averaged unquantised
uniform sampler2D u_radiance;
uniform sampler2D u_albedo;
uniform sampler2D u_material;
uniform sampler2D u_normal_depth;
uniform sampler2D u_uv;
uniform sampler2D u_display;
uniform int u_factor;

void main() {
    ivec2 base = ivec2(gl_FragCoord.xy) * u_factor;
    vec4 radiance = vec4(0.0), beauty = vec4(0.0);
    vec3 albedo = vec3(0.0), material = vec3(0.0), normal = vec3(0.0);
    float depth = 0.0, weight = 0.0;
    vec2 uv = vec2(0.0);
    for (int j = 0; j < u_factor; ++j) {
        for (int i = 0; i < u_factor; ++i) {
            ivec2 p = base + ivec2(i, j);
            vec4 a = texelFetch(u_albedo, p, 0);
            vec4 nd = texelFetch(u_normal_depth, p, 0);
            float c = a.a;
            radiance += texelFetch(u_radiance, p, 0);
            beauty += texelFetch(u_display, p, 0);
            albedo += c * a.rgb;
            material += c * texelFetch(u_material, p, 0).rgb;
            normal += c * nd.xyz;
            depth += c * nd.w;
            uv += c * texelFetch(u_uv, p, 0).xy;
            weight += c;
        }
    }
    float n = float(u_factor * u_factor);
    float inv = weight > 0.0 ? 1.0 / max(weight, 1e-12) : 0.0;
    normal *= inv;
    float len = length(normal);
    normal = len > 1e-8 ? normal / len : vec3(0.0);
    o_radiance = vec4(radiance.rgb / n, 0.0);
    o_albedo = vec4(albedo * inv, weight / n);
    o_material = vec4(material * inv, 0.0);
    o_normal_depth = vec4(normal, depth * inv);
    o_uv = vec4(uv * inv, 0.0, 0.0);
    o_beauty = vec4(beauty.rgb / n, 0.0);
}
