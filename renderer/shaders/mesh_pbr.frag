#version 430
#include "common.glsl"
// glTF 2.0 metallic-roughness shading under image-based lighting (split-sum, with Fdez-Aguera's
// multiple-scattering energy compensation), plus the G-buffer for the same fragment.
in vec3 v_world;
in vec3 v_normal;
in vec2 v_uv;
in vec4 v_tangent;
in vec4 v_color;

layout(location = 0) out vec4 o_radiance;  // linear HDR radiance, a = coverage
layout(location = 1) out vec4 o_albedo;    // linear base colour, a = coverage
layout(location = 2) out vec4 o_material;  // r roughness, g metallic, b occlusion, a = coverage
layout(location = 3) out vec4 o_normal;    // world shading normal, a = camera depth (OpenCV z)
layout(location = 4) out vec4 o_uv;        // texture coordinates (for checks and baking), a = coverage

uniform vec3 u_camera_position;
uniform vec3 u_camera_forward;

uniform vec4 u_base_color_factor;
uniform float u_metallic_factor;
uniform float u_roughness_factor;
uniform vec3 u_emissive_factor;
uniform float u_normal_scale;
uniform float u_occlusion_strength;
uniform int u_has_normal_texture;
uniform int u_alpha_mask;       // 1 for alphaMode MASK
uniform float u_alpha_cutoff;
uniform sampler2D u_base_color_texture;   // sRGB texture: sampled values are linear
uniform sampler2D u_metallic_roughness_texture;
uniform sampler2D u_normal_texture;
uniform sampler2D u_occlusion_texture;
uniform sampler2D u_emissive_texture;     // sRGB texture

uniform samplerCube u_specular_cube;      // GGX-prefiltered, roughness = lod / (levels - 1)
uniform samplerCube u_irradiance_cube;    // E / pi
uniform sampler2D u_brdf_lut;             // (A, B) by (N.V, roughness)
uniform float u_specular_max_lod;
uniform mat3 u_environment_rotation;      // world direction -> environment frame
uniform float u_environment_intensity;    // 2^exposure
uniform int u_multiple_scattering;

vec3 environment_direction(vec3 world_dir) { return u_environment_rotation * world_dir; }

void main() {
    vec4 base = u_base_color_factor * texture(u_base_color_texture, v_uv) * v_color;
    if (u_alpha_mask == 1 && base.a < u_alpha_cutoff) discard;
    vec4 mr = texture(u_metallic_roughness_texture, v_uv);
    float roughness = clamp(u_roughness_factor * mr.g, 0.0, 1.0);
    float metallic = clamp(u_metallic_factor * mr.b, 0.0, 1.0);
    float occlusion = 1.0 + u_occlusion_strength * (texture(u_occlusion_texture, v_uv).r - 1.0);
    vec3 emissive = u_emissive_factor * texture(u_emissive_texture, v_uv).rgb;

    vec3 n = normalize(v_normal);
    vec3 v = normalize(u_camera_position - v_world);
    // Back faces seen through double-sided materials (or open meshes) shade with the flipped normal.
    if (!gl_FrontFacing) n = -n;
    if (u_has_normal_texture == 1) {
        vec3 t = v_tangent.xyz - n * dot(n, v_tangent.xyz);
        if (dot(t, t) > 1e-12) {
            t = normalize(t);
            vec3 b = cross(n, t) * (v_tangent.w < 0.0 ? -1.0 : 1.0);
            if (!gl_FrontFacing) b = -b;
            vec3 tn = texture(u_normal_texture, v_uv).xyz * 2.0 - 1.0;
            tn.xy *= u_normal_scale;
            n = normalize(mat3(t, b, n) * tn);
        }
    }
    float n_dot_v = clamp(dot(n, v), 1e-4, 1.0);

    vec3 diffuse_color = base.rgb * (1.0 - metallic);
    vec3 f0 = mix(vec3(0.04), base.rgb, metallic);
    vec2 ab = texture(u_brdf_lut, vec2(n_dot_v, roughness)).rg;
    vec3 r = reflect(-v, n);
    vec3 radiance = textureLod(u_specular_cube, environment_direction(r), roughness * u_specular_max_lod).rgb;
    vec3 irradiance = texture(u_irradiance_cube, environment_direction(n)).rgb;

    // Roughness-dependent Fresnel (Fdez-Aguera 2019), single scattering F*E_ss.
    vec3 fr = max(vec3(1.0 - roughness), f0) - f0;
    vec3 k_s = f0 + fr * pow(1.0 - n_dot_v, 5.0);
    vec3 fss_ess = k_s * ab.x + ab.y;
    vec3 fms_ems = vec3(0.0);
    if (u_multiple_scattering == 1) {
        float ems = 1.0 - (ab.x + ab.y);
        vec3 f_avg = f0 + (1.0 - f0) / 21.0;
        fms_ems = ems * fss_ess * f_avg / (1.0 - f_avg * ems);
    }
    // Energy not reflected specularly (single + multiple) is what the diffuse layer receives.
    vec3 k_d = diffuse_color * (1.0 - fss_ess - fms_ems);
    vec3 color = (fss_ess * radiance + (fms_ems + k_d) * irradiance) * occlusion * u_environment_intensity;
    color += emissive;

    o_radiance = vec4(color, 1.0);
    o_albedo = vec4(base.rgb, 1.0);
    o_material = vec4(roughness, metallic, occlusion, 1.0);
    o_normal = vec4(n, dot(v_world - u_camera_position, u_camera_forward));
    o_uv = vec4(v_uv, 0.0, 1.0);
}
