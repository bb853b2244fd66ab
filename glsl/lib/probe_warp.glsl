// An adaptive probe layout (PROBE_WARP 1): along each axis a the probe planes sit at world
// fractions p_a[0] < ... < p_a[n_a - 1] of the probe box instead of (i + 0.5) / n_a. Plane i keeps
// texture coordinate (i + 0.5) / n_a, and a monotone piecewise-linear warp w_a maps a world fraction
// s to the texture coordinate u, linear between the planes (knots (0, 0), (p_a[i], (i + 0.5) / n_a),
// (1, 1)). Hardware trilinear filtering at the warped coordinate is then trilinear interpolation
// between the 8 surrounding probes at their real positions; beyond the outer planes it clamps to
// them, as the uniform grid does.
//
// One R32F texture `probe_warp` (app/rendering/probes/bake.py) holds, for axis a:
//   row a:     w_a tabulated at s = j / (columns - 1), j = 0 .. columns - 1 (16384 columns), read
//              with linear filtering: exact where w_a is linear (the identity warp included); in a
//              table step holding a plane off by at most about n_a / 16384 of a probe texel
//              (measured: 1.8% of a texel at 256 planes, 0.1% at 64);
//   row 3 + a: p_a[i] at column i (texelFetch), for probe_position.
// NumPy twin: app/twins/probe_warp.py. PROBE_WARP 0 (default) compiles none of this.
#ifndef PROBE_WARP
#define PROBE_WARP 0
#endif
#if PROBE_WARP
uniform sampler2D probe_warp;

// Texture coordinates of the probe textures at world fractions s of the probe box.
vec3 probe_warp_uvw(vec3 s)
{
    float columns = float(textureSize(probe_warp, 0).x);
    vec3 column = (clamp(s, 0.0, 1.0) * (columns - 1.0) + 0.5) / columns;
    return vec3(texture(probe_warp, vec2(column.x, 0.5 / 6.0)).r,
                texture(probe_warp, vec2(column.y, 1.5 / 6.0)).r,
                texture(probe_warp, vec2(column.z, 2.5 / 6.0)).r);
}

// World fractions of probe (i, j, k) in the probe box.
vec3 probe_warp_plane_fractions(uvec3 ijk)
{
    return vec3(texelFetch(probe_warp, ivec2(ijk.x, 3), 0).r,
                texelFetch(probe_warp, ivec2(ijk.y, 4), 0).r,
                texelFetch(probe_warp, ivec2(ijk.z, 5), 0).r);
}
#endif
