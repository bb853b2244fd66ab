// Probe bake, step 2: project this pass's walks onto SH (equal weights 4 pi / n over the rotated
// Fibonacci set), fold them into each probe's running mean and publish the probe textures (the
// first eight; probe_publish.comp the others).
// One work group per probe, one invocation per walk of the pass (at most 64 directions a pass,
// app/rendering/probes/bake.py DIRECTIONS_PER_PASS). Each invocation puts its walk's radiance (one array
// per colour) and SH basis in shared memory; then each channel (coefficient and colour) is summed
// over the walks by one invocation, or two where the channels leave invocations idle, and its
// running mean updated there: three barriers and no tree reduction. On an H100 (128^3 probes x
// 256 walks) this pass took 28 ms at order 2, 37 at order 3 and 55 at order 4, where a tree over
// 64 partial sums of every coefficient (12 KB of shared memory a group at order 3) and a serial
// update of every channel by one invocation took 36, 197 and 257 ms.
// Channel 27 (the sun's transmittance) was written by probe_sun.comp before the first pass.
layout(local_size_x = 64) in;

#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/sh.glsl"
#include "lib/directions.glsl"
#include "lib/probes.glsl"
#include "lib/probe_accum.glsl"
// this pass's new running means, which the publishing invocations read (lib/probe_publish.glsl)
shared float new_mean[PROBE_COLOUR_CHANNELS];
#define PROBE_MEAN(probe, f) new_mean[f]
#include "lib/probe_publish.glsl"

layout(std430, binding = 3) readonly buffer WalkRadiance { vec4 walk_radiance[]; };
uniform uint first_probe;
uniform uint directions;
uniform uint pass_index;
uniform uint seed;

shared float walk_colour[3][64];          // each walk's radiance (0 for one that does not count)
shared float walk_counts[64];             // 1 for a walk that counts
// its direction's SH basis, and with PROBE_SUN_LOBE the lobe's projection function there as
// coefficient SH_COUNT (= PROBE_LOBE_COEFFICIENT)
shared float walk_basis[64][SH_COUNT + PROBE_SUN_LOBE];

// Whether channel coefficient k is projected from the walks (the SH bands, and the sun lobe).
bool projected_coefficient(int k)
{
#if PROBE_SUN_LOBE
    if (k == PROBE_LOBE_COEFFICIENT)
        return true;
#endif
    return k >= 0 && k < SH_COUNT;
}

// Invocations per channel: the walks are split between them where the channels leave
// invocations idle (order 2: 28 channels, two invocations of 32 walks each).
#if PROBE_COLOUR_CHANNELS <= 32
#define PROJECT_SPLIT 2
shared float channel_part[64];
#else
#define PROJECT_SPLIT 1
#endif
const int WALKS_PER_PART = 64 / PROJECT_SPLIT;

// The channel's new running mean from its old one and this pass's projection.
float updated_mean(uint probe, int f, float projected, float to_mean, float weight)
{
    float mean = probes[probe].channels[f / 4][f % 4];
    int k = probe_colour_coefficient(f);
    if (projected_coefficient(k)) {
        if (pass_index == 0u)
            mean = 0.0;
        mean += (projected * to_mean - mean) * weight;
    } else if (k != PROBE_SUN_COEFFICIENT) {
        mean = 0.0;   // padding past the last coefficient
    }                 // the sun's transmittance (probe_sun.comp) stays
    return mean;
}

// Sum over walks [first, first + count) of one channel's radiance times its coefficient's basis.
float channel_sum(int f, int first, int count)
{
    int k = probe_colour_coefficient(f);
    if (!projected_coefficient(k))
        return 0.0;
    int colour = f - probe_colour_channel(k, 0);
    float sum = 0.0;
    for (int w = first; w < first + count; ++w)
        sum += walk_colour[colour][w] * walk_basis[w][k];
    return sum;
}

void main()
{
    uint tid = gl_LocalInvocationID.x;
    uint probe = first_probe + gl_WorkGroupID.x;
    vec3 previous_l00 = probes[probe].channels[0].rgb;   // read before any invocation writes

    vec3 radiance = vec3(0.0);
    float counts = 0.0;
    float basis[SH_COUNT];
    for (int k = 0; k < SH_COUNT; ++k)
        basis[k] = 0.0;
    float lobe = 0.0;
    if (tid < directions) {
        vec4 walk = walk_radiance[gl_WorkGroupID.x * directions + tid];
        if (walk.a == 1.0) {   // else dropped (2), or not walked: the probe had converged (3)
            radiance = walk.rgb;
            counts = 1.0;
            vec3 omega = probe_walk_direction(probe, pass_index, tid, directions, seed);
            sh_basis(omega, basis);
#if PROBE_SUN_LOBE
            lobe = sun_lobe_basis(dot(omega, sun_direction), sun_lobe_phase_g, sun_lobe_g,
                                  PROBE_SH_ORDER);
#endif
        }
    }
    walk_colour[0][tid] = radiance.r;
    walk_colour[1][tid] = radiance.g;
    walk_colour[2][tid] = radiance.b;
    walk_counts[tid] = counts;
    for (int k = 0; k < SH_COUNT; ++k)
        walk_basis[tid][k] = basis[k];
#if PROBE_SUN_LOBE
    walk_basis[tid][PROBE_LOBE_COEFFICIENT] = lobe;
#endif
    barrier();

    float n = 0.0;
    for (int w = 0; w < 64; ++w)
        n += walk_counts[w];
    float samples_before = pass_index == 0u ? 0.0 : probes[probe].samples;
    float weight = n > 0.0 ? n / (samples_before + n) : 0.0;
    float to_mean = n > 0.0 ? 4.0 * 3.14159265358979 / n : 0.0;
#if PROJECT_SPLIT > 1
    if (tid < uint(PROBE_COLOUR_CHANNELS * PROJECT_SPLIT)) {
        int part = int(tid) % PROJECT_SPLIT;
        channel_part[tid] = channel_sum(int(tid) / PROJECT_SPLIT, part * WALKS_PER_PART,
                                        WALKS_PER_PART);
    }
    barrier();
    if (tid < uint(PROBE_COLOUR_CHANNELS)) {
        float projected = 0.0;
        for (int part = 0; part < PROJECT_SPLIT; ++part)
            projected += channel_part[tid * uint(PROJECT_SPLIT) + uint(part)];
        new_mean[tid] = updated_mean(probe, int(tid), projected, to_mean, weight);
    }
#else
    for (uint f = tid; f < uint(PROBE_COLOUR_CHANNELS); f += 64u)
        new_mean[f] = updated_mean(probe, int(f), channel_sum(int(f), 0, 64), to_mean, weight);
#endif
    barrier();   // every channel's new mean in shared memory, every old one read

    for (uint f = tid; f < uint(PROBE_COLOUR_CHANNELS); f += 64u)
        probes[probe].channels[f / 4u][f % 4u] = new_mean[f];
    if (tid == 0u) {
        float square = 0.0;   // sum over the walks of v^2, v = mean over rgb of a walk's radiance
        for (int w = 0; w < 64; ++w) {
            float v = (walk_colour[0][w] + walk_colour[1][w] + walk_colour[2][w]) / 3.0;
            square += v * v;
        }
        float square_before = pass_index == 0u ? 0.0 : probes[probe].square_mean;
        probes[probe].square_mean = n > 0.0 ? square_before + (square / n - square_before) * weight
                                            : square_before;
        probes[probe].samples = samples_before + n;
        vec3 l00 = vec3(new_mean[0], new_mean[1], new_mean[2]);
        vec3 delta = l00 - previous_l00;
        probes[probe].change = pass_index == 0u ? 0.0 : dot(delta, delta);
        probes[probe].magnitude = dot(l00, l00);
    }
    // one invocation a texture; the image array's index stays the loop's (dynamically uniform)
    for (int i = 0; i < PROBE_PUBLISH_COUNT; ++i)
        if (int(tid) == i)
            probe_publish_texture(probe, i, samples_before + n);
}
