// Probe bake, step 1: random walks. One invocation per (probe, direction) of this pass and chunk;
// each walk is a path from the probe (lib/integrator.glsl), resumable like the path tracer's, and
// leaves its radiance estimate in walk_radiance (a: 1 valid, 2 dropped, 0 not finished).
layout(local_size_x = 64) in;

#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/phase.glsl"
#include "lib/tracking.glsl"
#include "lib/directions.glsl"
#include "lib/probes.glsl"
#include "lib/integrator.glsl"

layout(std430, binding = 1) buffer WalkStates { PathState walks[]; };
layout(std430, binding = 2) buffer Progress { uint walks_with_work; };
layout(std430, binding = 3) buffer WalkRadiance { vec4 walk_radiance[]; };

uniform uint first_probe;     // chunk offset
uniform uint chunk_probes;    // probes in this chunk
uniform uint directions;      // walks per probe in this pass
uniform uint pass_index;
uniform uint seed;
uniform int loop_budget;
uniform int loop_reserve;

void main()
{
    uint local = gl_GlobalInvocationID.x;
    if (local >= chunk_probes * directions)
        return;
    if (walk_radiance[local].a != 0.0)
        return;  // finished in an earlier dispatch
    uint probe = first_probe + local / directions;
    uint slot = local % directions;
    PathState p = walks[local];
    if (p.status == PATH_IDLE) {
        vec3 omega = probe_walk_direction(probe, pass_index, slot, directions, seed);
        uint key = probe * directions + slot;
        path_begin(p, probe_position(probe), omega, rng_seed(key, pass_index, seed));
    }
    int budget = loop_budget;
    int result = path_continue(p, budget, loop_reserve);
    if (result == PATH_SUSPENDED) {
        walks[local] = p;
        atomicAdd(walks_with_work, 1u);
        return;
    }
    p.status = PATH_IDLE;
    walks[local] = p;
    walk_radiance[local] = path_estimate_valid(p, result) ? vec4(p.radiance, 1.0) : vec4(0.0, 0.0, 0.0, 2.0);
}
