// Visibility-weighted probe interpolation (PROBE_VISIBILITY 1; 0, the default, compiles none of
// this and lib/probes.glsl reads the probes through hardware trilinear filtering alone).
//
// Trilinear interpolation blends the 8 probes around a point x whatever lies between x and them:
// a probe inside an opaque block sees no light and darkens the surfaces next to it, and a probe on
// the lit side of a thin dense wall lights the medium on its shadowed side. Here each probe's
// trilinear weight w_i is multiplied by its visibility from x,
//     v_i = exp(-(e_i - min_j e_j)),   e_i = max(0, tau_i - sigma_t(x) |p_i - x|),
// tau_i the optical depth of the straight segment from x to probe i at p_i, estimated from
// PROBE_VISIBILITY_SAMPLES midpoint samples of sigma_t (default 1): e_i is the extinction on the way
// beyond what x's own medium would give over that length, 0 in a homogeneous medium. The weights
// w_i v_i are renormalised (measured from the least occluded probe, so that a point enclosed on all
// sides keeps the trilinear blend rather than none).
//
// Measured (bench/h100-visibility): raymarch error 1-14% lower on foot, bonsai, fuel and the thick
// cloud at 64^3 and up; up to 45% higher on the smooth clouds at 8^3 (the way to a denser core is
// a gradient there, not a wall) and 5% on the anisotropic cloud at 32^3; the frame 1.8-2.8x as
// long. As the default the benchmark reached 30 of 32 targets later, so it is opt-in. Rejected:
// weights only for points optically thin over a probe spacing (exp(-sigma_t(x) h) e_i: most of the
// gain went, so the dense surfaces the interior probes darken are what the weights fix), any
// difference from sigma_t(x) counted (|...|: worse on foot and bonsai), 2 or 4 samples a way (the
// errors of 1, 1.3x the frame), one hardware fetch at the weights' centroid (no faster).
//
// Where every v_i >= 1 - PROBE_VISIBILITY_TOLERANCE (each weight within that factor of trilinear;
// known without sampling where even a way through the majorant could not do more) the hardware
// trilinear fetch is used, bit for bit the PROBE_VISIBILITY 0 result; elsewhere each texture is
// read as 8 weighted texelFetch. Cost: 8 x PROBE_VISIBILITY_SAMPLES + 1 sigma_t lookups per probe
// read, plus the 8 fetches per texture where a probe is occluded.
// NumPy twin: app/twins/probe_visibility.py.
#include "lib/medium.glsl"
#ifndef PROBE_VISIBILITY
#define PROBE_VISIBILITY 0
#endif
#ifndef PROBE_VISIBILITY_SAMPLES
#define PROBE_VISIBILITY_SAMPLES 1
#endif
#if PROBE_VISIBILITY
const float PROBE_VISIBILITY_TOLERANCE = 0.01;
// PROBE_VISIBILITY_MAX_CELL: the widest probe spacing over the uniform one (1, or an adaptive
// layout's bound, probe_planes.py MAX_SPACING), from app/rendering/renderer.py
#ifndef PROBE_VISIBILITY_MAX_CELL
#error "PROBE_VISIBILITY_MAX_CELL: set by app/rendering/renderer.py with PROBE_VISIBILITY"
#endif

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
    vec3 spacing = probe_box_size / vec3(probe_grid);
    // no way to a probe is longer than a cell's diagonal nor denser than the majorant: where even
    // that could not move a weight past the tolerance, the trilinear fetch is the answer
    if (PROBE_VISIBILITY_MAX_CELL * length(spacing) * (majorant - sigma_x)
            < PROBE_VISIBILITY_TOLERANCE)
        return false;
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
