// Probe bake, step 2: project this pass's walks onto SH (equal weights 4 pi / n over the rotated
// Fibonacci set), fold them into each probe's running mean and publish the probe textures (the
// first eight; probe_publish.comp the others).
// One work group per probe; the group's invocations share its walks and reduce in shared memory.
// Channel 27 (the sun's transmittance) was written by probe_sun.comp before the first pass.
layout(local_size_x = 64) in;

#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/sh.glsl"
#include "lib/directions.glsl"
#include "lib/probes.glsl"
#include "lib/probe_accum.glsl"
#include "lib/probe_publish.glsl"

layout(std430, binding = 3) readonly buffer WalkRadiance { vec4 walk_radiance[]; };
uniform uint first_probe;
uniform uint directions;
uniform uint pass_index;
uniform uint seed;

shared vec3 partial[64][SH_COUNT];
shared uint partial_count[64];
shared float partial_square[64];

void main()
{
    uint tid = gl_LocalInvocationID.x;
    uint probe = first_probe + gl_WorkGroupID.x;
    uint base = gl_WorkGroupID.x * directions;
    vec3 sum[SH_COUNT];
    for (int k = 0; k < SH_COUNT; ++k)
        sum[k] = vec3(0.0);
    uint count = 0u;
    float square = 0.0;
    for (uint slot = tid; slot < directions; slot += 64u) {
        vec4 walk = walk_radiance[base + slot];
        if (walk.a != 1.0)
            continue;   // dropped (2), or not walked: the probe had converged (3)
        float v = (walk.r + walk.g + walk.b) / 3.0;
        square += v * v;
        float basis[SH_COUNT];
        sh_basis(probe_walk_direction(probe, pass_index, slot, directions, seed), basis);
        for (int k = 0; k < SH_COUNT; ++k)
            sum[k] += walk.rgb * basis[k];
        count += 1u;
    }
    for (int k = 0; k < SH_COUNT; ++k)
        partial[tid][k] = sum[k];
    partial_count[tid] = count;
    partial_square[tid] = square;
    barrier();
    for (uint stride = 32u; stride > 0u; stride >>= 1u) {
        if (tid < stride) {
            for (int k = 0; k < SH_COUNT; ++k)
                partial[tid][k] += partial[tid + stride][k];
            partial_count[tid] += partial_count[tid + stride];
            partial_square[tid] += partial_square[tid + stride];
        }
        barrier();
    }
    if (tid != 0u)
        return;

    ProbeAccum acc = probes[probe];
    if (pass_index == 0u) {
        float sun_transmittance = acc.channels[6].a;   // probe_sun.comp
        for (int t = 0; t < PROBE_COLOUR_TEXTURES; ++t)
            acc.channels[t] = vec4(0.0);
        acc.samples = 0.0;
        acc.square_mean = 0.0;
        acc.channels[6].a = sun_transmittance;
    }
    uint n = partial_count[0];
    vec3 previous_l00 = acc.channels[0].rgb;
    if (n > 0u) {
        float total = acc.samples + float(n);
        float weight = float(n) / total;
        for (int k = 0; k < SH_COUNT; ++k) {
            vec3 projected = partial[0][k] * (4.0 * 3.14159265358979 / float(n));
            for (int c = 0; c < 3; ++c) {
                int f = probe_colour_channel(k, c);
                acc.channels[f / 4][f % 4] += (projected[c] - acc.channels[f / 4][f % 4]) * weight;
            }
        }
        acc.square_mean += (partial_square[0] / float(n) - acc.square_mean) * weight;
        acc.samples = total;
    }
    vec3 l00 = acc.channels[0].rgb;
    vec3 delta = l00 - previous_l00;
    acc.change = pass_index == 0u ? 0.0 : dot(delta, delta);
    acc.magnitude = dot(l00, l00);
    probes[probe] = acc;
    probe_publish(probe, acc);
}
