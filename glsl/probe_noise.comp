// The adaptive bake's noise target (lib/probe_noise.glsl), after the first pass: one work group
// averages the walk variance over all probes.
layout(local_size_x = 256) in;

#include "lib/probe_accum.glsl"
#include "lib/probe_noise.glsl"

uniform uint probe_count;
uniform float adaptive_factor;   // target = factor^2 x mean variance / walks_asked
uniform float walks_asked;       // walks per probe of the whole bake

shared float partial[256];

void main()
{
    uint tid = gl_LocalInvocationID.x;
    float sum = 0.0;
    for (uint probe = tid; probe < probe_count; probe += 256u)
        sum += probe_walk_variance(probes[probe]);
    partial[tid] = sum;
    barrier();
    for (uint stride = 128u; stride > 0u; stride >>= 1u) {
        if (tid < stride)
            partial[tid] += partial[tid + stride];
        barrier();
    }
    if (tid == 0u) {
        mean_walk_variance = partial[0] / float(probe_count);
        noise_target_squared = adaptive_factor * adaptive_factor * mean_walk_variance / walks_asked;
    }
}
