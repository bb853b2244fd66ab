// Radiance probes: an nx x ny x nz grid over the probe box (the region the transfer function makes
// visible, or the whole volume box). Probe (i, j, k) sits at the texel centre ((i + 0.5) / nx, ...)
// of its RGBA 3D textures (seven up to SH order 2), so hardware trilinear filtering blends the 8
// nearest probes (and clamps to the outer probes beyond them, where the medium is empty anyway).
//
// What the textures hold and where: lib/probe_packing.glsl (SH coefficients of bands 0 ..
// PROBE_SH_ORDER, colour or grey, and channel 27, the sun's transmittance from the probe to the
// box boundary, which the probes-only mode multiplies with the exact phase function instead of
// tracing a shadow ray).
//
// A probe stores incident radiance L_in(omega), arriving from omega, of light that scattered at
// least once on its way plus the attenuated environment; the unscattered sun beam is left out (it
// is direct light, added at render time).
//
// PROBE_SUN_LOBE (0 or 1; default 0): 1 adds to the convolved bands a lobe about the sun's
// direction, whose amplitude the probes hold beside their coefficients (lib/sun_lobe.glsl; order 3,
// where app/rendering/probes/layout.py sun_lobe_g turns it on for forward scattering).
//
// PROBE_WARP (0 or 1; default 0): 1 places the probe planes of each axis where an adaptive layout
// put them (lib/probe_warp.glsl) instead of evenly; the textures and their packing are the same.
#include "lib/probe_packing.glsl"
#include "lib/probe_warp.glsl"
// used where PROBE_SUN_LOBE; included here whatever the build (each file is included once, so
// not inside an #if)
#include "lib/sun_lobe.glsl"
uniform ivec3 probe_grid;
// The textures hold the SH coefficients divided by this (the scene's brightest light, as radiance:
// app/rendering/probes/bake.py radiance_scale), so that 16-bit texels keep their range and precision
// whatever units the scene's lights use; the sun's transmittance is stored as it is.
uniform float probe_radiance_scale;
uniform vec3 probe_box_min;    // world corner of the probe box
uniform vec3 probe_box_size;   // its size (> 0 on every axis)

// Probe (i, j, k) of index i + nx (j + ny k): its texel in the probe textures.
uvec3 probe_ijk(uint probe_index)
{
    uint nx = uint(probe_grid.x), ny = uint(probe_grid.y);
    return uvec3(probe_index % nx, (probe_index / nx) % ny, probe_index / (nx * ny));
}

// World position of probe (i, j, k).
vec3 probe_world_position(ivec3 ijk)
{
#if PROBE_WARP
    return probe_box_min + probe_warp_plane_fractions(uvec3(ijk)) * probe_box_size;
#else
    return probe_box_min + (vec3(ijk) + 0.5) / vec3(probe_grid) * probe_box_size;
#endif
}

vec3 probe_position(uint probe_index)
{
    return probe_world_position(ivec3(probe_ijk(probe_index)));
}

#include "lib/probe_visibility.glsl"

// Direction `slot` of a pass's spherical Fibonacci set, turned by a random rotation drawn per probe
// and per pass, so that passes and neighbouring probes sample different directions.
vec3 probe_walk_direction(uint probe_index, uint pass_index, uint slot, uint directions, uint seed)
{
    uint rng = rng_seed(probe_index, pass_index, seed ^ 0x5bd1e995u);
    mat3 rotation = random_rotation(rng_next(rng), rng_next(rng), rng_next(rng));
    return rotation * fibonacci_direction(slot, directions);
}

#ifdef PROBE_SAMPLING
#if PROBE_SUN_LOBE
vec3 probe_fetched_lobe;          // the sun lobe's amplitude that probe_fetch read last
#endif
// The textures this build reads, by slot (lib/probe_packing.glsl; app/rendering/probes/bake.py binds them).
uniform sampler3D probe_textures[PROBE_TEXTURE_COUNT];
// per SH band: g^l (the phase convolution) times the SH window
uniform float probe_band_factors[SH_BANDS];
// per SH band: the window alone (g = 1): the probes' radiance itself, h(w), which `guided`'s
// direction control reads (lib/guided_direction_control.glsl)
uniform float probe_window_factors[SH_BANDS];

// Texture `slot` of the probes at texture coordinate uvw: hardware trilinear, or where
// PROBE_VISIBILITY found an occluded probe, the visibility-weighted blend of the 8 around it.
#if PROBE_VISIBILITY
#define PROBE_TEXEL(s) (occluded ? probe_corners_texel(probe_textures[s], corners) : texture(probe_textures[s], uvw))
#else
#define PROBE_TEXEL(slot) texture(probe_textures[slot], uvw)
#endif

// Trilinearly interpolated (PROBE_VISIBILITY: visibility-weighted) SH coefficients and sun
// transmittance at world point x, the coefficients (and the sun lobe) times `scale`; coefficients
// above PROBE_SH_ORDER read as 0. probe_fetch below: scaled to radiance.
void probe_fetch_scaled(vec3 x, out vec3 coeffs[SH_COUNT], out float sun_transmittance,
                        float scale)
{
#if PROBE_WARP
    vec3 uvw = probe_warp_uvw((x - probe_box_min) / probe_box_size);
#else
    vec3 uvw = (x - probe_box_min) / probe_box_size;
#endif
#if PROBE_VISIBILITY
    ProbeCorners corners;
    bool occluded = probe_visibility_corners(x, uvw, corners);
#endif
    for (int k = 0; k < SH_COUNT; ++k)
        coeffs[k] = vec3(0.0);
#if !PROBE_GREY && PROBE_SH_ORDER <= 1
    // Colour orders 0 and 1 skip textures 1 .. 5 or 3 .. 5, so their slots are not the texture
    // numbers; written out, every index stays a constant (the loop below with a slot mapping put
    // the fetched texels in local memory on an H100: 2 to 4% of a `probes` frame).
    vec4 t0 = PROBE_TEXEL(0);
    vec4 t6 = PROBE_TEXEL(PROBE_TEXTURE_COUNT - 1);
    coeffs[0] = t0.rgb;
#if PROBE_SH_ORDER == 1
    vec4 t1 = PROBE_TEXEL(1), t2 = PROBE_TEXEL(2);
    coeffs[1] = vec3(t0.a, t1.rg);
    coeffs[2] = vec3(t1.ba, t2.r);
    coeffs[3] = t2.gba;
#endif
    sun_transmittance = clamp(t6.a, 0.0, 1.0);
#else
    vec4 texel[PROBE_TEXTURE_COUNT];   // slot = texture number from here on
    for (int slot = 0; slot < PROBE_TEXTURE_COUNT; ++slot)
        texel[slot] = PROBE_TEXEL(slot);
    for (int k = 0; k < PROBE_SH_COEFFS; ++k) {
#if PROBE_GREY
        int f = k < 3 ? k : k + 1;
        coeffs[k] = vec3(texel[f / 4][f % 4]);
#else
        for (int c = 0; c < 3; ++c) {
            int f = probe_colour_channel(k, c);
            coeffs[k][c] = texel[f / 4][f % 4];
        }
#endif
    }
#if PROBE_GREY
    sun_transmittance = clamp(texel[0].a, 0.0, 1.0);
#else
    sun_transmittance = clamp(texel[6].a, 0.0, 1.0);
#endif
#if PROBE_SUN_LOBE && PROBE_GREY
    probe_fetched_lobe = vec3(texel[(PROBE_LOBE_COEFFICIENT + 1) / 4][(PROBE_LOBE_COEFFICIENT + 1) % 4]
                              * scale);
#elif PROBE_SUN_LOBE
    for (int c = 0; c < 3; ++c) {
        int f = probe_colour_channel(PROBE_LOBE_COEFFICIENT, c);
        probe_fetched_lobe[c] = texel[f / 4][f % 4] * scale;
    }
#endif
#endif
    for (int k = 0; k < PROBE_SH_COEFFS; ++k)
        coeffs[k] *= scale;
}

// The probes' radiance coefficients and sun transmittance at x (probe_fetch_scaled).
void probe_fetch(vec3 x, out vec3 coeffs[SH_COUNT], out float sun_transmittance)
{
    probe_fetch_scaled(x, coeffs, sun_transmittance, probe_radiance_scale);
}

// Radiance in-scattered towards a ray travelling along d, from coefficients probe_fetch has just
// fetched (their sun lobe included): the probes' radiance convolved with the phase function, never
// negative (SH ringing is clamped).
vec3 probe_inscattered_from(vec3 coeffs[SH_COUNT], vec3 d)
{
#if defined(PHASE_ISOTROPIC)
    // g = 0 (SceneResources.defines, with surfaces): the bands above 0 are scaled by g^l =
    // 0, so the sum is its first term alone, band 0's factor times c_00 Y_00, in the order
    // sh_evaluate_convolved takes it; the surfaces' bands 1 and 2 are not read into it (on an H200
    // the foot's 1080p frame with surfaces 2.73 -> 2.59 ms: bench/h200-hybrid-cost)
    vec3 inscattered = probe_band_factors[0] * (coeffs[0] * SH_C0);
#else
    vec3 inscattered = sh_evaluate_convolved(coeffs, d, probe_band_factors);
#endif
#if PROBE_SUN_LOBE
    inscattered += probe_fetched_lobe
                   * sun_lobe_convolved(dot(d, sun_direction), sun_lobe_phase_g, PROBE_SH_ORDER);
#endif
    return sh_clamp_nonnegative(inscattered);
}

// The same at world point x (the fetch included).
vec3 probe_inscattered(vec3 x, vec3 d, out float sun_transmittance)
{
    vec3 coeffs[SH_COUNT];
    probe_fetch(x, coeffs, sun_transmittance);
    return probe_inscattered_from(coeffs, d);
}
#endif
