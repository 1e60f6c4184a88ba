#version 430
#include "common.glsl"
// The environment seen through each pixel, written under the meshes (coverage 0 everywhere).
in vec2 v_ndc;
layout(location = 0) out vec4 o_radiance;
layout(location = 1) out vec4 o_albedo;
layout(location = 2) out vec4 o_material;
layout(location = 3) out vec4 o_normal;
layout(location = 4) out vec4 o_uv;
uniform samplerCube u_environment_cube;
uniform mat3 u_environment_rotation;
uniform float u_environment_intensity;
uniform float u_background_lod;  // > 0 blurs the backdrop
uniform int u_show_environment;
// OpenCV intrinsics and rotation of the camera: the pixel's ray in world space.
uniform vec4 u_intrinsics;       // fx, fy, cx, cy (pixels)
uniform vec2 u_image_size;
uniform mat3 u_camera_rotation;  // camera -> world (OpenCV axes)

void main() {
    // gl_FragCoord has its origin at the bottom-left; OpenCV rows grow downward.
    vec2 pixel = vec2(gl_FragCoord.x, u_image_size.y - gl_FragCoord.y);
    vec3 d_cam = vec3((pixel.x - u_intrinsics.z) / u_intrinsics.x, (pixel.y - u_intrinsics.w) / u_intrinsics.y, 1.0);
    vec3 d = normalize(u_camera_rotation * d_cam);
    vec3 env = textureLod(u_environment_cube, u_environment_rotation * d, u_background_lod).rgb;
    o_radiance = vec4(u_show_environment == 1 ? env * u_environment_intensity : vec3(0.0), 0.0);
    o_albedo = vec4(0.0);
    o_material = vec4(0.0);
    o_normal = vec4(0.0);
    o_uv = vec4(0.0);
}
