// Probe bake, step 0 (before the first pass): the sun's transmittance from each probe to the box
// boundary (channel 27, which probes-only reads), one invocation per probe. Its own dispatch, so
// the benchmark's bake profile times it apart from the walks and the projection.
//
// PROBE_SUN_GRID (defined when the walks read the light grid, which is then baked and bound): one
// filtered fetch of the light grid at the probe, the same sun the raymarcher and the walks see.
// Otherwise a march from the probe to the boundary (lib/shadow_march.glsl). The march is a chain
// of dependent fetches as long as the volume is deep, one invocation per probe: on an H100 it took
// 0.04 to 0.07 ms for the 300 to 500 probes of an 8^3 grid (0.34 ms on the foot), as long as the
// walks themselves on hydrogen (bench/h100-small).
layout(local_size_x = 64) in;

#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/rng.glsl"
#include "lib/directions.glsl"
#include "lib/probes.glsl"
#if defined(PROBE_SUN_GRID)
#include "lib/light_grid.glsl"
#else
#include "lib/shadow_march.glsl"
#endif
#include "lib/probe_accum.glsl"

uniform uint probe_count;

void main()
{
    uint probe = gl_GlobalInvocationID.x;
    if (probe >= probe_count)
        return;
    CHECK_INDEX(probe, probes.length(), CHECK_SITE_PROBE_INDEX);
#if defined(PROBE_SUN_GRID)
    probes[probe].channels[6].a = light_grid_transmittance(probe_position(probe));
#else
    probes[probe].channels[6].a = sun_transmittance_march(probe_position(probe));
#endif
}
