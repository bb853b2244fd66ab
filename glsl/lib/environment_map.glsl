// An equirectangular environment map (SPEC.md, Mitsuba 3's envmap convention) and its importance
// sampling; NumPy twin: app/twins/environment_map.py (the conventions are spelled out there).
// Built only with ENVIRONMENT_MAP defined (lib/lights.glsl includes it then); the constant
// environment's build does not contain this file.
//
// A direction d reads the map at u = frac(atan2(d.x, -d.z) / 2 pi), v = acos(d.y) / pi, pixel
// centres at ((j + 0.5) / W, (i + 0.5) / H), bilinear, wrapping in u and clamped in v (row 0 is
// +y); the map is turned by the scene's rotation about +y. Sampling picks a row from the marginal
// CDF, a column from that row's conditional CDF and a point inside the pixel uniformly.
uniform sampler2D environment_map;   // RGBA32F W x H: rgb radiance, a the density over (u, v)
uniform sampler2D environment_cdf;   // R32F (W + 1) x (H + 1): row i < H row i's CDF, row H the rows'
uniform ivec2 environment_size;      // W, H
uniform float environment_scale;     // radiance multiplier
uniform vec2 environment_rotation;   // cos and sin of the map's rotation about +y

const float ENVIRONMENT_PI = 3.14159265358979;

// World direction -> the map's frame: R_y(-rotation) d.
vec3 environment_to_map(vec3 d)
{
    float c = environment_rotation.x, s = environment_rotation.y;
    return vec3(c * d.x - s * d.z, d.y, s * d.x + c * d.z);
}

// The map's frame -> world: R_y(rotation) m.
vec3 environment_from_map(vec3 m)
{
    float c = environment_rotation.x, s = environment_rotation.y;
    return vec3(c * m.x + s * m.z, m.y, -s * m.x + c * m.z);
}

// SPEC.md's (u, v) of a unit direction in the map's frame.
vec2 environment_uv(vec3 m)
{
    float u = atan(m.x, -m.z) / (2.0 * ENVIRONMENT_PI);
    u -= floor(u);
    // acos(m.y) for a unit m, written as an atan: GLSL's acos is loose (llvmpipe's is 3e-5 off).
    float v = atan(length(m.xz), m.y) / ENVIRONMENT_PI;
    return vec2(u, v);
}

// The map's rgb at (u, v): bilinear between pixel centres, wrapping in u, clamped in v.
vec3 environment_bilinear(vec2 uv)
{
    int w = environment_size.x, h = environment_size.y;
    vec2 p = uv * vec2(environment_size) - 0.5;
    vec2 p0 = floor(p);
    vec2 f = p - p0;
    int j0 = (int(p0.x) + w) % w;        // p0.x >= -1
    int j1 = (j0 + 1) % w;
    int i0 = clamp(int(p0.y), 0, h - 1);
    int i1 = clamp(int(p0.y) + 1, 0, h - 1);
    vec3 top = mix(texelFetch(environment_map, ivec2(j0, i0), 0).rgb,
                   texelFetch(environment_map, ivec2(j1, i0), 0).rgb, f.x);
    vec3 bottom = mix(texelFetch(environment_map, ivec2(j0, i1), 0).rgb,
                      texelFetch(environment_map, ivec2(j1, i1), 0).rgb, f.x);
    return mix(top, bottom, f.y);
}

// Radiance arriving from world direction d (unit, from the scene towards the sky).
vec3 environment_radiance(vec3 d)
{
    return environment_scale * environment_bilinear(environment_uv(environment_to_map(d)));
}

float environment_cdf_at(int column, int row)
{
    return texelFetch(environment_cdf, ivec2(column, row), 0).r;
}

// The largest k < n with cdf[k] <= x in row `row` of the CDF texture (its n + 1 entries run 0..1).
int environment_search(int row, int n, float x)
{
    int lo = 0, hi = n;
    while (hi - lo > 1) {
        int mid = (lo + hi) / 2;
        if (environment_cdf_at(mid, row) <= x)
            lo = mid;
        else
            hi = mid;
    }
    return lo;
}

// Solid-angle density of environment_sample at pixel (j, i) and sin(theta) of the point.
float environment_pdf_at(int j, int i, float sin_theta)
{
    float pdf_uv = texelFetch(environment_map, ivec2(j, i), 0).a;
    return sin_theta > 0.0 ? pdf_uv / (2.0 * ENVIRONMENT_PI * ENVIRONMENT_PI * sin_theta) : 0.0;
}

// A world direction drawn from the map's distribution for uniform numbers u1 (row) and u2
// (column), and its solid-angle pdf (0 only at the poles, where the sample must be dropped).
vec3 environment_sample(float u1, float u2, out float pdf)
{
    int w = environment_size.x, h = environment_size.y;
    int i = environment_search(h, h, u1);
    float m0 = environment_cdf_at(i, h), m1 = environment_cdf_at(i + 1, h);
    float dv = clamp((u1 - m0) / (m1 - m0), 0.0, 1.0);
    int j = environment_search(i, w, u2);
    float c0 = environment_cdf_at(j, i), c1 = environment_cdf_at(j + 1, i);
    float du = clamp((u2 - c0) / (c1 - c0), 0.0, 1.0);
    float theta = ENVIRONMENT_PI * (float(i) + dv) / float(h);
    float phi = 2.0 * ENVIRONMENT_PI * (float(j) + du) / float(w);
    float s = sin(theta);
    pdf = environment_pdf_at(j, i, s);
    return environment_from_map(vec3(s * sin(phi), cos(theta), -s * cos(phi)));
}

// Solid-angle pdf of environment_sample returning world direction d.
float environment_pdf(vec3 d)
{
    vec3 m = environment_to_map(d);
    vec2 uv = environment_uv(m);
    int w = environment_size.x, h = environment_size.y;
    int j = min(int(uv.x * float(w)), w - 1);
    int i = min(int(uv.y * float(h)), h - 1);
    return environment_pdf_at(j, i, sqrt(max((1.0 - m.y) * (1.0 + m.y), 0.0)));
}
