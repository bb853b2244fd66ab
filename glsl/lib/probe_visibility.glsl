// Visibility-weighted probe interpolation (PROBE_VISIBILITY 1; 0, the default, compiles none of
// this and lib/probes.glsl reads the probes through hardware trilinear filtering alone).
//
// Trilinear interpolation blends the 8 probes around a point x whatever lies between x and them:
// a probe inside an opaque block sees no light and darkens the thin medium next to the block, and a
// probe on the lit side of a thin dense wall lights the medium on its shadowed side. Here each
// probe's trilinear weight w_i is multiplied by its visibility from x,
//     v_i = exp(-(e_i - min_j e_j)),   e_i = max(0, tau_i - sigma_t(x) |p_i - x|),
// tau_i the optical depth of the straight segment from x to probe i at p_i, estimated from
// PROBE_VISIBILITY_SAMPLES midpoint samples of sigma_t: e_i is the extinction on the way beyond what
// x's own medium would give over that length. So in a homogeneous medium, and from a point inside
// matter at least as dense as anything on the way to its probes (the surface layer of a dense
// region, whose image needs the dark probes inside it), every v_i = 1 and the blend is trilinear
// as before; only probes behind matter denser than x's surroundings lose weight. The weights
// w_i v_i are renormalised (measured from the least occluded probe, so that a point enclosed on
// all sides keeps the trilinear blend rather than none).
//
// Measured (bench/h100-visibility): raymarch error 1-14% lower on foot, bonsai and fuel, up to 5%
// higher on the anisotropic cloud at 32^3; the frame 1.8-4.3x as long. Counting any difference
// from sigma_t(x) (|tau_i - sigma_t(x) |p_i - x||, so that a point in dense matter drops the thin
// medium's probes too) made foot and bonsai worse; 4 samples a segment gave the errors of 2.
//
// Where every v_i >= 1 - PROBE_VISIBILITY_TOLERANCE (each weight within that factor of trilinear)
// the hardware trilinear fetch is used, bit for bit the PROBE_VISIBILITY 0 result; elsewhere each
// texture is read as 8 weighted texelFetch. Cost: 8 x PROBE_VISIBILITY_SAMPLES + 1 sigma_t lookups
// per probe read, plus the 8 fetches per texture where a probe is occluded.
// NumPy twin: app/twins/probe_visibility.py.
#include "lib/medium.glsl"
#ifndef PROBE_VISIBILITY
#define PROBE_VISIBILITY 0
#endif
#ifndef PROBE_VISIBILITY_SAMPLES
#define PROBE_VISIBILITY_SAMPLES 2
#endif
#if PROBE_VISIBILITY
const float PROBE_VISIBILITY_TOLERANCE = 0.01;

// The 8 probes around a point and their normalised weights; corner c is base + (c & 1, (c >> 1) & 1,
// c >> 2), clamped to the grid (beyond the outer probes both corners of an axis are the outer one,
// as with the textures' clamp-to-edge).
struct ProbeCorners {
    ivec3 base;
    float weight[8];
};

ivec3 probe_corner(ivec3 base, int c)
{
    return clamp(base + ivec3(c & 1, (c >> 1) & 1, c >> 2), ivec3(0), probe_grid - 1);
}

// e_i above: optical depth from x to p beyond sigma_x over the same length, never negative.
float probe_excess_optical_depth(vec3 x, float sigma_x, vec3 p)
{
    vec3 segment = p - x;
    float sigma_sum = 0.0;
    for (int j = 0; j < PROBE_VISIBILITY_SAMPLES; ++j)
        sigma_sum += sigma_t_at(x + ((float(j) + 0.5) / float(PROBE_VISIBILITY_SAMPLES)) * segment);
    return max(length(segment) * (sigma_sum / float(PROBE_VISIBILITY_SAMPLES) - sigma_x), 0.0);
}

// The corners of x (texture coordinate uvw) and their weights; true when some probe is occluded
// (a weight differs from trilinear by more than the tolerance), false to fetch trilinearly.
bool probe_visibility_corners(vec3 x, vec3 uvw, out ProbeCorners corners)
{
    vec3 c = uvw * vec3(probe_grid) - 0.5;
    vec3 lower = floor(c);
    vec3 f = c - lower;
    corners.base = ivec3(lower);
    float sigma_x = sigma_t_at(x);
    float excess[8];
    float least = 1e30;
    for (int k = 0; k < 8; ++k) {
        excess[k] = probe_excess_optical_depth(x, sigma_x,
                                               probe_world_position(probe_corner(corners.base, k)));
        least = min(least, excess[k]);
    }
    bool occluded = false;
    float total = 0.0;
    for (int k = 0; k < 8; ++k) {
        float visibility = exp(least - excess[k]);
        occluded = occluded || visibility < 1.0 - PROBE_VISIBILITY_TOLERANCE;
        vec3 t = vec3(k & 1, (k >> 1) & 1, k >> 2);
        vec3 w3 = mix(1.0 - f, f, t);
        corners.weight[k] = w3.x * w3.y * w3.z * visibility;
        total += corners.weight[k];
    }
    // total >= the least occluded probe's trilinear weight; 0 only where x sits on probes' planes
    // with every probe of non-zero weight occluded, which the trilinear fetch then answers
    if (!(total > 0.0))
        return false;
    for (int k = 0; k < 8; ++k)
        corners.weight[k] /= total;
    return occluded;
}

// One probe texture at the corners' weights.
vec4 probe_corners_texel(sampler3D probe_texture, ProbeCorners corners)
{
    vec4 sum = vec4(0.0);
    for (int k = 0; k < 8; ++k)
        sum += corners.weight[k] * texelFetch(probe_texture, probe_corner(corners.base, k), 0);
    return sum;
}
#endif
