// The participating medium of SPEC.md (post-classification): density from a 3D texture
// (cell-centred, trilinear, clamped to the edge voxel), a transfer function table, and the box;
// a crop box and a clip plane cut it (lib/clip_region.glsl). NumPy twin: app/twins/medium.py.
//
// Several channels (SPEC.md, Channels; MEDIUM_CHANNELS > 1, up to 4): one density per channel in
// the texture's components, one table per channel (row c of the table texture), and the medium
// is their mixture, made here and nowhere else (classified_at): sigma_t = sum of the channels'
// sigma_t, the albedo their sigma_t-weighted mix; a channel switched off (channel_on 0) adds
// exactly nothing. With one channel (MEDIUM_CHANNELS 1, the default) the code is the one-channel
// medium's, unchanged.
#include "lib/checks.glsl"
#include "lib/clip_region.glsl"
#include "lib/brick_pool.glsl"
#if !defined(MEDIUM_CHANNELS)
#define MEDIUM_CHANNELS 1
#endif
uniform sampler3D volume_density;     // normalised density in [0, 1] (one component a channel)
uniform sampler2D transfer_function;  // N x C RGBA32F, entries at densities linspace(0, 1, N)
uniform int transfer_size;            // N (channel 0's)
#if MEDIUM_CHANNELS > 1
uniform ivec4 channel_transfer_size;  // each channel's N
uniform int transfer_stride;          // rows of the table texture (the buffer's entries a channel)
uniform vec4 channel_on;              // 1 shown, 0 switched off
#endif
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
#define CHANNEL_TRANSFER_ENTRY(c, i) transfer_entries[(c) * transfer_stride + (i)]
#else
#define TRANSFER_ENTRY(i) texelFetch(transfer_function, ivec2(i, 0), 0)
#define CHANNEL_TRANSFER_ENTRY(c, i) texelFetch(transfer_function, ivec2(i, c), 0)
#endif

// A bricked volume (VOLUME_BRICKED, lib/brick_pool.glsl) reads the same values through its page
// table; without it the code is the one-texture medium's, unchanged.
float density_at(vec3 p)
{
#if VOLUME_BRICKED
    return bricked_sample(kept_sample_point(p) / (2.0 * box_half_extent) + 0.5).r;
#else
    return texture(volume_density, kept_sample_point(p) / (2.0 * box_half_extent) + 0.5).r;
#endif
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

#if MEDIUM_CHANNELS > 1
// Each channel's normalised density at p (components past MEDIUM_CHANNELS unused).
vec4 densities_at(vec3 p)
{
#if VOLUME_BRICKED
    return bricked_sample(kept_sample_point(p) / (2.0 * box_half_extent) + 0.5);
#else
    return texture(volume_density, kept_sample_point(p) / (2.0 * box_half_extent) + 0.5);
#endif
}

// Channel c's transfer function at density d (transfer_at of its own table).
vec4 channel_transfer_at(int c, float d)
{
    int n = channel_transfer_size[c];
    float x = clamp(d, 0.0, 1.0) * float(n - 1);
    int i0 = min(int(x), n - 2);
    CHECK_INDEX(i0, n - 1, CHECK_SITE_TRANSFER_ENTRY);
    vec4 a = CHANNEL_TRANSFER_ENTRY(c, i0);
    vec4 b = CHANNEL_TRANSFER_ENTRY(c, i0 + 1);
    return a + (b - a) * (x - float(i0));
}

// The channels' mixture at densities d: opacity (sigma_t / density_scale) the sum of the
// channels' opacities, colour their opacity-weighted mean (0 where no channel has opacity; no
// light scatters there). With density_scale common to all channels, the weights are the
// channels' sigma_t: sigma_s = sigma_t albedo rgb = density_scale albedo sum_c a_c rgb_c.
vec4 mixed_transfer_at(vec4 d)
{
    float a = 0.0;
    vec3 weighted = vec3(0.0);
    for (int c = 0; c < MEDIUM_CHANNELS; ++c) {
        vec4 tf = channel_transfer_at(c, d[c]);
        float a_c = channel_on[c] * tf.a;
        a += a_c;
        weighted += a_c * tf.rgb;
    }
    return vec4(a > 0.0 ? weighted / a : vec3(0.0), a);
}
#endif

// The transfer function's RGBA at p (of several channels, their mixture): zero where the crop
// or the clip plane cut the medium away (the one place that test is made; sigma_t_at and the
// raymarcher read the medium through it).
vec4 classified_at(vec3 p)
{
#if MEDIUM_CHANNELS > 1
    return kept_at(p) ? mixed_transfer_at(densities_at(p)) : vec4(0.0);
#else
    return kept_at(p) ? transfer_at(density_at(p)) : vec4(0.0);
#endif
}

// sigma_t and the single-scattering albedo per colour (sigma_s / sigma_t) of a transfer-function
// RGBA (classified_at's): for a caller that needs both from one lookup.
float sigma_t_of(vec4 classified)
{
    return density_scale * classified.a;
}

vec3 albedo_of(vec4 classified)
{
    return albedo * classified.rgb;
}

float sigma_t_at(vec3 p)
{
    return sigma_t_of(classified_at(p));
}

// Single-scattering albedo per colour (sigma_s / sigma_t) at p.
vec3 albedo_at(vec3 p)
{
#if MEDIUM_CHANNELS > 1
    return albedo_of(mixed_transfer_at(densities_at(p)));
#else
    return albedo_of(transfer_at(density_at(p)));
#endif
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
