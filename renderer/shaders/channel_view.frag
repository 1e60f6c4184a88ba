#version 430
#include "common.glsl"
// One G-buffer channel for display (the viewport's albedo / roughness / metallic / normal views):
// albedo sRGB-encoded, scalars as grey, normals as 0.5 n + 0.5; empty pixels a neutral grey.
in vec2 v_ndc;
layout(location = 0) out vec4 o_color;
uniform sampler2D u_albedo;        // rgb linear base colour, a = coverage
uniform sampler2D u_material;      // r roughness, g metallic
uniform sampler2D u_normal_depth;  // xyz world normal
uniform int u_channel;             // 0 albedo, 1 roughness, 2 metallic, 3 normal
uniform vec3 u_empty;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec4 albedo = texelFetch(u_albedo, p, 0);
    float coverage = albedo.a;
    vec3 c;
    if (u_channel == 0) c = linear_to_srgb(clamp(albedo.rgb / max(coverage, 1e-6), 0.0, 1.0));
    else if (u_channel == 1) c = vec3(texelFetch(u_material, p, 0).r / max(coverage, 1e-6));
    else if (u_channel == 2) c = vec3(texelFetch(u_material, p, 0).g / max(coverage, 1e-6));
    else c = 0.5 * normalize(texelFetch(u_normal_depth, p, 0).xyz + vec3(1e-9)) + 0.5;
    o_color = vec4(mix(u_empty, clamp(c, 0.0, 1.0), clamp(coverage, 0.0, 1.0)), 1.0);
}
