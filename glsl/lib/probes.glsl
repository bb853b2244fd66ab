// Radiance probes: an nx x ny x nz grid over the probe box (the region the transfer function makes
// visible, or the whole volume box). Probe (i, j, k) sits at the texel centre ((i + 0.5) / nx, ...)
// of up to seven RGBA 3D textures, so hardware trilinear filtering blends the 8 nearest probes (and
// clamps to the outer probes beyond them, where the medium is empty anyway).
//
// Packing of the 28 channels: channel f = 4 * texture + component (texture 0..6, component rgba).
// For f < 27: SH coefficient k = f / 3 (order of lib/sh.glsl), colour = f % 3 (r, g, b).
// f = 27 (texture 6, alpha): the sun's transmittance from the probe to the box boundary, which the
// probes-only mode multiplies with the exact phase function instead of tracing a shadow ray.
//
// A probe stores incident radiance L_in(omega), arriving from omega, of light that scattered at
// least once on its way plus the attenuated environment; the unscattered sun beam is left out (it
// is direct light, added at render time).
//
// PROBE_SH_ORDER (0, 1 or 2; default 2) keeps bands up to that order: order 0 uses textures 0 and 6,
// order 1 textures 0, 1, 2 and 6 (app/render/probe_layout.py); the others are neither allocated
// nor read, and their coefficients read as 0.
//
// PROBE_GREY (0 or 1; default 0): when the transfer function's colours and both lights are grey,
// every probe's r, g and b are equal, and one channel is stored: f = 0, 1, 2 hold coefficients
// 0, 1, 2; f = 3 the sun's transmittance; f = 4 + (k - 3) coefficient k >= 3. Order 0 then needs
// texture 0 alone, order 1 textures 0 and 1, order 2 textures 0, 1 and 2.
//
// PROBE_WARP (0 or 1; default 0): 1 places the probe planes of each axis where an adaptive layout
// put them (lib/probe_warp.glsl) instead of evenly; the textures and their packing are the same.
#ifndef PROBE_SH_ORDER
#define PROBE_SH_ORDER 2
#endif
#ifndef PROBE_GREY
#define PROBE_GREY 0
#endif
#include "lib/probe_warp.glsl"
uniform ivec3 probe_grid;
// The textures hold the SH coefficients divided by this (the scene's brightest light, as radiance:
// app/render/probes.py radiance_scale), so that 16-bit texels keep their range and precision
// whatever units the scene's lights use; the sun's transmittance is stored as it is.
uniform float probe_radiance_scale;
uniform vec3 probe_box_min;    // world corner of the probe box
uniform vec3 probe_box_size;   // its size (> 0 on every axis)

vec3 probe_position(uint probe_index)
{
    uint nx = uint(probe_grid.x), ny = uint(probe_grid.y);
    uvec3 ijk = uvec3(probe_index % nx, (probe_index / nx) % ny, probe_index / (nx * ny));
#if PROBE_WARP
    return probe_box_min + probe_warp_plane_fractions(ijk) * probe_box_size;
#else
    return probe_box_min + (vec3(ijk) + 0.5) / vec3(probe_grid) * probe_box_size;
#endif
}

// Direction `slot` of a pass's spherical Fibonacci set, turned by a random rotation drawn per probe
// and per pass, so that passes and neighbouring probes sample different directions.
vec3 probe_walk_direction(uint probe_index, uint pass_index, uint slot, uint directions, uint seed)
{
    uint rng = rng_seed(probe_index, pass_index, seed ^ 0x5bd1e995u);
    mat3 rotation = random_rotation(rng_next(rng), rng_next(rng), rng_next(rng));
    return rotation * fibonacci_direction(slot, directions);
}

#ifdef PROBE_SAMPLING
#if PROBE_GREY
uniform sampler3D probe_sh0;
#if PROBE_SH_ORDER >= 1
uniform sampler3D probe_sh1;
#endif
#if PROBE_SH_ORDER >= 2
uniform sampler3D probe_sh2;
#endif
#else
uniform sampler3D probe_sh0, probe_sh6;
#if PROBE_SH_ORDER >= 1
uniform sampler3D probe_sh1, probe_sh2;
#endif
#if PROBE_SH_ORDER >= 2
uniform sampler3D probe_sh3, probe_sh4, probe_sh5;
#endif
#endif
uniform vec3 probe_band_factors;  // per SH band: g^l (phase convolution) times the SH window

// Trilinearly interpolated SH coefficients and sun transmittance at world point x.
void probe_fetch(vec3 x, out vec3 coeffs[9], out float sun_transmittance)
{
#if PROBE_WARP
    vec3 uvw = probe_warp_uvw((x - probe_box_min) / probe_box_size);
#else
    vec3 uvw = (x - probe_box_min) / probe_box_size;
#endif
    for (int k = 1; k < 9; ++k)
        coeffs[k] = vec3(0.0);
#if PROBE_GREY
    vec4 t0 = texture(probe_sh0, uvw);
    coeffs[0] = vec3(t0.r);
#if PROBE_SH_ORDER >= 1
    vec4 t1 = texture(probe_sh1, uvw);
    coeffs[1] = vec3(t0.g);
    coeffs[2] = vec3(t0.b);
    coeffs[3] = vec3(t1.r);
#endif
#if PROBE_SH_ORDER >= 2
    vec4 t2 = texture(probe_sh2, uvw);
    coeffs[4] = vec3(t1.g);
    coeffs[5] = vec3(t1.b);
    coeffs[6] = vec3(t1.a);
    coeffs[7] = vec3(t2.r);
    coeffs[8] = vec3(t2.g);
#endif
    sun_transmittance = clamp(t0.a, 0.0, 1.0);
#else
    vec4 t0 = texture(probe_sh0, uvw);
    vec4 t6 = texture(probe_sh6, uvw);
    coeffs[0] = t0.rgb;
#if PROBE_SH_ORDER >= 1
    vec4 t1 = texture(probe_sh1, uvw), t2 = texture(probe_sh2, uvw);
    coeffs[1] = vec3(t0.a, t1.rg);
    coeffs[2] = vec3(t1.ba, t2.r);
    coeffs[3] = t2.gba;
#endif
#if PROBE_SH_ORDER >= 2
    vec4 t3 = texture(probe_sh3, uvw), t4 = texture(probe_sh4, uvw), t5 = texture(probe_sh5, uvw);
    coeffs[4] = t3.rgb;
    coeffs[5] = vec3(t3.a, t4.rg);
    coeffs[6] = vec3(t4.ba, t5.r);
    coeffs[7] = t5.gba;
    coeffs[8] = t6.rgb;
#endif
    sun_transmittance = clamp(t6.a, 0.0, 1.0);
#endif
    for (int k = 0; k < 9; ++k)
        coeffs[k] *= probe_radiance_scale;
}

// Radiance in-scattered towards a ray travelling along d at x, from the probes' radiance convolved
// with the phase function, never negative (SH ringing is clamped).
vec3 probe_inscattered(vec3 x, vec3 d, out float sun_transmittance)
{
    vec3 coeffs[9];
    probe_fetch(x, coeffs, sun_transmittance);
    return sh_clamp_nonnegative(sh_evaluate_convolved(coeffs, d, probe_band_factors));
}
#endif
