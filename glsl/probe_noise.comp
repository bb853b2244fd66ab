// The adaptive bake (lib/probe_noise.glsl), when the first pass ends: one work group sums the
// walk variance over all probes; probe_walk_budget.comp then sets each probe's passes from it.
layout(local_size_x = 256) in;

#include "lib/probe_accum.glsl"
#include "lib/probe_noise.glsl"

uniform uint probe_count;

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
        noise_variance_sum = partial[0];
        noise_probe_count = float(probe_count);
    }
}
