// Probe bake, step 3 for orders 3 and 4: publishes the texture slots past the first eight that
// probe_project.comp wrote (lib/probe_publish.glsl), for the probes it just folded in; one
// invocation per probe of the chunk. Built once per group of at most eight slots
// (PROBE_PUBLISH_FIRST = 8, 16).
layout(local_size_x = 64) in;

#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/directions.glsl"
#include "lib/probes.glsl"
#include "lib/probe_accum.glsl"
#include "lib/probe_publish.glsl"

uniform uint first_probe;
uniform uint chunk_probes;

void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= chunk_probes)
        return;
    uint probe = first_probe + i;
    float samples = probes[probe].samples;
    for (int slot = 0; slot < PROBE_PUBLISH_COUNT; ++slot)
        probe_publish_texture(probe, slot, samples);
}
