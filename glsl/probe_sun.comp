// Probe bake, step 0 (before the first pass): the sun's transmittance from each probe to the box
// boundary (channel 27, which probes-only reads), one invocation per probe. Its own dispatch, so
// the benchmark's bake profile times it apart from the walks and the projection.
layout(local_size_x = 64) in;

#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/rng.glsl"
#include "lib/directions.glsl"
#include "lib/probes.glsl"
#include "lib/shadow_march.glsl"
#include "lib/probe_accum.glsl"

uniform uint probe_count;

void main()
{
    uint probe = gl_GlobalInvocationID.x;
    if (probe >= probe_count)
        return;
    probes[probe].channels[6].a = sun_transmittance_march(probe_position(probe));
}
