#version 430
#include "common.glsl"
// Exposure, ACES filmic curve (Stephen Hill's fit of the RRT + ODT) and the sRGB transfer function.
// renderer/tonemap.py holds the identical numpy reference.
in vec2 v_ndc;
layout(location = 0) out vec4 o_color;
uniform sampler2D u_radiance;  // linear HDR, a = coverage
uniform float u_exposure;      // 2^EV
uniform int u_tonemapper;      // 0 = ACES fit, 1 = linear clamp

const mat3 ACES_INPUT = mat3(0.59719, 0.07600, 0.02840, 0.35458, 0.90834, 0.13383, 0.04823, 0.01566, 0.83777);
const mat3 ACES_OUTPUT = mat3(1.60475, -0.10208, -0.00327, -0.53108, 1.10813, -0.07276, -0.07367, -0.00605, 1.07602);

vec3 rrt_odt_fit(vec3 v) {
    vec3 a = v * (v + 0.0245786) - 0.000090537;
    vec3 b = v * (0.983729 * v + 0.4329510) + 0.238081;
    return a / b;
}

void main() {
    vec4 hdr = texelFetch(u_radiance, ivec2(gl_FragCoord.xy), 0);
    vec3 c = max(hdr.rgb * u_exposure, 0.0);
    if (u_tonemapper == 0) c = ACES_OUTPUT * rrt_odt_fit(ACES_INPUT * c);
    o_color = vec4(linear_to_srgb(clamp(c, 0.0, 1.0)), hdr.a);
}
