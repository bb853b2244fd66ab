// Probe bake, step 1b (walks with the sun from the light grid, WALK_SUN_GRID): each walk's one
// correction of the grid's sun (lib/integrator.glsl path_flight chose the event, weighted
// reservoir sampling). Adds weight * (T_ray - T_grid) to the walk's radiance, T_ray a
// ratio-tracked shadow ray towards the sun from the chosen point: unbiased for the walk's sum of
// c_k (T_ray,k - T_grid,k) over its events. Its own pass so that the walks' shader holds no
// shadow ray: there its code made every walk 2-2.5x slower on an H100, traced or not.
// A shadow ray that runs out of steps drops its walk (counted in tracking_stats, as a truncated
// path is).
layout(local_size_x = 64) in;

#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/tracking.glsl"
#include "lib/sun_shadow.glsl"

layout(std430, binding = 3) buffer WalkRadiance { vec4 walk_radiance[]; };

uniform uint walk_count;     // walks in this chunk
uniform uint first_probe;    // the chunk's first probe
uniform uint directions;     // walks per probe in this pass (a walk's key: probe * directions + slot)
uniform uint pass_index;
uniform uint seed;
uniform int loop_budget;     // tracking steps one ray may take (the dispatch's loop budget)

void main()
{
    uint local = gl_GlobalInvocationID.x;
    if (local >= walk_count || walk_radiance[local].a != 1.0)
        return;
    uint base = uint(walk_radiance.length()) / 3u;
    CHECK_INDEX(base + 2u * local + 1u, walk_radiance.length(), CHECK_SITE_WALK_INDEX);
    vec4 chosen = walk_radiance[base + 2u * local + 1u];   // c / w and the factor W / Q
    if (!(chosen.w > 0.0))
        return;
    vec3 weight = chosen.rgb * chosen.w;
    if (all(equal(weight, vec3(0.0))))
        return;
    vec4 at = walk_radiance[base + 2u * local];
    // keyed by the walk (as its own stream is, another seed): the same however a pass is cut
    uint rng = rng_seed(first_probe * directions + local, pass_index, seed ^ 0x68e31da4u);
    int steps = loop_budget;
    float transmittance = sun_transmittance(at.xyz, rng, steps);
    if (transmittance < 0.0) {
        atomicAdd(tracking_stats.truncated_paths, 1u);
        walk_radiance[local] = vec4(0.0, 0.0, 0.0, 2.0);
        return;
    }
    walk_radiance[local].rgb += weight * (transmittance - at.w);
}
