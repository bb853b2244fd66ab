// A bake's progress without reading every probe back (ProbeGrid.progress_report): the sums over
// probes of each probe's last squared change of L00 and its squared L00 (lib/probe_accum.glsl),
// reduced per workgroup in shared memory; the host adds the few partial sums. NumPy twin: the
// same two column sums of the probes' accumulators (tests/test_bake.py).
layout(local_size_x = 256) in;
#include "lib/probe_accum.glsl"

layout(std430, binding = 0) writeonly buffer PartialSums { vec2 partial_sums[]; };
uniform uint probe_count;

shared vec2 group_sums[256];

void main()
{
    uint i = gl_GlobalInvocationID.x, lane = gl_LocalInvocationID.x;
    group_sums[lane] = i < probe_count ? vec2(probes[i].change, probes[i].magnitude) : vec2(0.0);
    barrier();
    for (uint stride = 128u; stride > 0u; stride >>= 1) {
        if (lane < stride)
            group_sums[lane] += group_sums[lane + stride];
        barrier();
    }
    if (lane == 0u)
        partial_sums[gl_WorkGroupID.x] = group_sums[0];
}
