// The participating medium of SPEC.md (post-classification): density from a 3D texture
// (cell-centred, trilinear, clamped to the edge voxel), a transfer function table, and the box;
// a crop box and a clip plane cut it (lib/clip_region.glsl). NumPy twin: app/twins/medium.py.
#include "lib/checks.glsl"
#include "lib/clip_region.glsl"
uniform sampler3D volume_density;     // normalised density in [0, 1]
uniform sampler2D transfer_function;  // N x 1 RGBA32F, entries at densities linspace(0, 1, N)
uniform int transfer_size;            // N
uniform float density_scale;
uniform float albedo;
uniform vec3 box_half_extent;
uniform float majorant;               // >= sigma_t everywhere in the box

// The transfer table's entry i. Every tracking step waits on this lookup after its density fetch.
// TRANSFER_FROM_BUFFER (compute passes on a GPU, app/gl/shaders.py transfer_from_buffer): from a
// storage buffer holding the same floats as the texture (app/gl/textures.py TransferTable), a
// load through the data cache that waits less than a texelFetch through the texture unit; else
// (fragment shaders, which need not have storage buffers, and llvmpipe) from the texture.
#if !defined(TRANSFER_FROM_BUFFER)
#define TRANSFER_FROM_BUFFER 0
#endif
#if TRANSFER_FROM_BUFFER
layout(std430, binding = 8) readonly buffer TransferTable { vec4 transfer_entries[]; };
#define TRANSFER_ENTRY(i) transfer_entries[i]
#else
#define TRANSFER_ENTRY(i) texelFetch(transfer_function, ivec2(i, 0), 0)
#endif

float density_at(vec3 p)
{
    return texture(volume_density, kept_sample_point(p) / (2.0 * box_half_extent) + 0.5).r;
}

// Linear interpolation between table entries, written a + (b - a) f so that equal entries give
// exactly that entry (an albedo of exactly 1 must stay 1 over millions of bounces).
vec4 transfer_at(float d)
{
    float x = clamp(d, 0.0, 1.0) * float(transfer_size - 1);
    int i0 = min(int(x), transfer_size - 2);
    CHECK_INDEX(i0, transfer_size - 1, CHECK_SITE_TRANSFER_ENTRY);
    vec4 a = TRANSFER_ENTRY(i0);
    vec4 b = TRANSFER_ENTRY(i0 + 1);
    return a + (b - a) * (x - float(i0));
}

// The transfer function's RGBA at p: zero where the crop or the clip plane cut the medium away
// (the one place that test is made; sigma_t_at and the raymarcher read the medium through it).
vec4 classified_at(vec3 p)
{
    return kept_at(p) ? transfer_at(density_at(p)) : vec4(0.0);
}

float sigma_t_at(vec3 p)
{
    return density_scale * classified_at(p).a;
}

// Single-scattering albedo per channel (sigma_s / sigma_t) at p.
vec3 albedo_at(vec3 p)
{
    return albedo * transfer_at(density_at(p)).rgb;
}

// Slab test against the volume box (the kept box where a crop or clip plane is on: beyond it
// the medium is vacuum); robust to zero direction components.
bool box_intersect(vec3 origin, vec3 direction, out float t_near, out float t_far)
{
    vec3 inv = 1.0 / mix(direction, vec3(1e-30), equal(direction, vec3(0.0)));
    vec3 ta = ((clip_region_on == 0 ? -box_half_extent : kept_box_min) - origin) * inv;
    vec3 tb = ((clip_region_on == 0 ? box_half_extent : kept_box_max) - origin) * inv;
    vec3 tmin = min(ta, tb);
    vec3 tmax = max(ta, tb);
    t_near = max(max(tmin.x, tmin.y), max(tmin.z, 0.0));
    t_far = min(min(tmax.x, tmax.y), tmax.z);
    return t_far > t_near;
}
