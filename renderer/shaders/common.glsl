// Shared constants and conventions. Mirrors renderer/environment.py (equirect mapping) and
// renderer/tonemap.py (sRGB). Pulled into other shaders by shader_source.py.
const float PI = 3.14159265358979323846;

// World direction -> equirectangular (u, v): image centre looks along +X, row 0 is the zenith (+Z).
vec2 direction_to_equirect_uv(vec3 d) {
    d = normalize(d);
    float u = 0.5 - atan(d.y, d.x) / (2.0 * PI);
    float v = acos(clamp(d.z, -1.0, 1.0)) / PI;
    return vec2(fract(u), v);
}

// OpenGL cube-map face texel -> world direction (the inverse of the GL spec's face selection).
// st in [-1, 1], face 0..5 = +X -X +Y -Y +Z -Z.
vec3 cube_face_direction(int face, vec2 st) {
    float s = st.x;
    float t = st.y;
    vec3 d;
    if (face == 0) d = vec3(1.0, -t, -s);
    else if (face == 1) d = vec3(-1.0, -t, s);
    else if (face == 2) d = vec3(s, 1.0, t);
    else if (face == 3) d = vec3(s, -1.0, -t);
    else if (face == 4) d = vec3(s, -t, 1.0);
    else d = vec3(-s, -t, -1.0);
    return normalize(d);
}

// Direction of the centre of texel (x, y) of a cube face of the given size.
vec3 cube_texel_direction(int face, ivec2 texel, int size) {
    vec2 st = (vec2(texel) + 0.5) / float(size) * 2.0 - 1.0;
    return cube_face_direction(face, st);
}

// Solid angle of a cube-map texel (exact, from the area element of the unit cube face).
float cube_texel_solid_angle(ivec2 texel, int size) {
    float inv = 1.0 / float(size);
    vec2 a = vec2(texel) * 2.0 * inv - 1.0;
    vec2 b = (vec2(texel) + 1.0) * 2.0 * inv - 1.0;
    #define AREA(x, y) atan((x) * (y), sqrt((x) * (x) + (y) * (y) + 1.0))
    return AREA(a.x, a.y) - AREA(a.x, b.y) - AREA(b.x, a.y) + AREA(b.x, b.y);
    #undef AREA
}

float linear_to_srgb_channel(float c) {
    return c <= 0.0031308 ? 12.92 * c : 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

vec3 linear_to_srgb(vec3 c) {
    return vec3(linear_to_srgb_channel(c.r), linear_to_srgb_channel(c.g), linear_to_srgb_channel(c.b));
}

// Van der Corput radical inverse: low-discrepancy sample sequences for the integrators.
vec2 hammersley(uint i, uint n) {
    uint bits = i;
    bits = (bits << 16u) | (bits >> 16u);
    bits = ((bits & 0x55555555u) << 1u) | ((bits & 0xAAAAAAAAu) >> 1u);
    bits = ((bits & 0x33333333u) << 2u) | ((bits & 0xCCCCCCCCu) >> 2u);
    bits = ((bits & 0x0F0F0F0Fu) << 4u) | ((bits & 0xF0F0F0F0u) >> 4u);
    bits = ((bits & 0x00FF00FFu) << 8u) | ((bits & 0xFF00FF00u) >> 8u);
    return vec2(float(i) / float(n), float(bits) * 2.3283064365386963e-10);
}

// Orthonormal basis around n (Frisvad / Duff et al.).
mat3 basis_around(vec3 n) {
    float sign_z = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (sign_z + n.z);
    float b = n.x * n.y * a;
    vec3 t = vec3(1.0 + sign_z * n.x * n.x * a, sign_z * b, -sign_z * n.x);
    vec3 bt = vec3(b, sign_z + n.y * n.y * a, -n.y);
    return mat3(t, bt, n);
}
