// Probe bake, step 1: random walks. One invocation per (probe, direction) of this pass and chunk;
// each walk is a path from the probe (lib/integrator.glsl) and leaves its radiance estimate in
// walk_radiance (a: 1 valid, 2 dropped, 0 not finished).
//
// RESUMABLE_WALKS 1 (drivers with a loop limit, llvmpipe): a walk runs until the dispatch's loop
// budget is low, keeps its state in walks[] and the host dispatches again while walks_with_work > 0.
// The first dispatch of a chunk (first_dispatch = 1) ignores what the buffers hold from the last
// chunk, so nothing is cleared from the CPU. RESUMABLE_WALKS 0 (no loop limit): every walk runs to
// its end in one dispatch; there is no walk state at all, and nothing is read back.
//
// With adaptive_walks != 0, a probe whose budget (decided from its neighbours when the first pass
// ended, lib/probe_noise.glsl) does not reach this pass takes no walks in it: its walks leave
// a = 3 and the projection leaves it as it is.
//
// WALK_SUN_GRID (defined or not): the sun at each scattering event from the baked light grid
// (lib/light_grid.glsl) instead of a ratio-tracked shadow ray, corrected without bias by one
// shadow ray a walk at most, traced after the walks (glsl/probe_sun_correction.comp). The buffer
// walk_radiance then holds three entries a walk: the radiance first, then two for that ray.
layout(local_size_x = 64) in;

#ifndef RESUMABLE_WALKS
#define RESUMABLE_WALKS 1
#endif

#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/phase.glsl"
#include "lib/tracking.glsl"
#include "lib/directions.glsl"
#include "lib/probes.glsl"
#if defined(WALK_SUN_GRID)
#define LIGHT_GRID_FACE_MARCH 0
#endif
#include "lib/light_grid.glsl"
#include "lib/sun_shadow.glsl"
// the integrator's walks: a walk adds no light it meets before scattering from the area lights
// (lib/integrator.glsl AREA_LIGHTS), as it adds no direct sun
#define PROBE_WALKS
#include "lib/integrator.glsl"
#include "lib/walk_profile.glsl"
#include "lib/probe_accum.glsl"
#include "lib/probe_noise.glsl"

#if RESUMABLE_WALKS
layout(std430, binding = 1) buffer WalkStates { PathState walks[]; };
layout(std430, binding = 2) buffer Progress { uint walks_with_work; };
uniform uint first_dispatch;  // 1: start every walk of the chunk afresh
#endif
layout(std430, binding = 3) buffer WalkRadiance { vec4 walk_radiance[]; };

#if defined(WALK_SUN_GRID) && defined(WALK_SUN_CORRECTION)
// The sun's correction a walk chose, for probe_sun_correction.comp, in the buffer's second region
// (two entries a walk after the chunk's radiance): its point and grid transmittance, then its
// c / w and (written as the walk ends) the factor W / Q that makes it unbiased, 0 where none.
uint walk_slot;   // the running walk's index in the chunk

void walk_correction_choose(vec3 x, float grid, vec3 weight_per_w)
{
    uint base = uint(walk_radiance.length()) / 3u;
    walk_radiance[base + 2u * walk_slot] = vec4(x, grid);
    walk_radiance[base + 2u * walk_slot + 1u] = vec4(weight_per_w, 0.0);
}
#endif

uniform uint first_probe;     // chunk offset
uniform uint chunk_probes;    // probes in this chunk
uniform uint directions;      // walks per probe in this pass
uniform uint pass_index;
uniform uint seed;
uniform int loop_budget;
uniform int loop_reserve;
uniform int adaptive_walks;   // 1: skip probes whose walk budget ends before this pass

// Walk `local` of the chunk from its start to its end (or, resumable, to the dispatch's budget).
void run_walk(uint local)
{
    uint probe = first_probe + local / directions;
    uint slot = local % directions;
    CHECK_INDEX(probe, probes.length(), CHECK_SITE_PROBE_INDEX);
    CHECK_INDEX(local, walk_radiance.length(), CHECK_SITE_WALK_INDEX);
#if RESUMABLE_WALKS
    CHECK_INDEX(local, walks.length(), CHECK_SITE_WALK_INDEX);
#endif
    PathState p;
#if RESUMABLE_WALKS
    bool fresh = first_dispatch != 0u;
#else
    const bool fresh = true;
#endif
    if (fresh && adaptive_walks != 0 && !probe_takes_pass(probe, pass_index)) {
        walk_radiance[local] = vec4(0.0, 0.0, 0.0, 3.0);
        return;
    }
#if RESUMABLE_WALKS
    if (!fresh) {
        if (walk_radiance[local].a != 0.0)
            return;  // finished in an earlier dispatch
        p = walks[local];
        fresh = p.status == PATH_IDLE;
    }
#endif
    if (fresh) {
        vec3 omega = probe_walk_direction(probe, pass_index, slot, directions, seed);
        uint key = probe * directions + slot;
        path_begin(p, probe_position(probe), omega, rng_seed(key, pass_index, seed));
    }
    int budget = loop_budget;
#if defined(WALK_SUN_GRID) && defined(WALK_SUN_CORRECTION)
    walk_slot = local;
#endif
    int result = path_continue(p, budget, loop_reserve);
    walk_profile_flush(result == PATH_SUSPENDED ? 0 : 1, p.bounce);
#if RESUMABLE_WALKS
    if (result == PATH_SUSPENDED) {
        walks[local] = p;
        walk_radiance[local] = vec4(0.0);
        atomicAdd(walks_with_work, 1u);
        return;
    }
#endif
    bool valid = path_estimate_valid(p, result);
    walk_radiance[local] = valid ? vec4(p.radiance, 1.0) : vec4(0.0, 0.0, 0.0, 2.0);
#if defined(WALK_SUN_GRID) && defined(WALK_SUN_CORRECTION)
    // Whether the correction the walk chose (walk_correction_choose) is traced, with probability
    // Q = min(1, sum of its rates), and its factor W / Q; 0: none (no event chosen, or not drawn).
    if (valid) {
        uint base = uint(walk_radiance.length()) / 3u;
        float rate = min(1.0, p.correction_rate_sum);
        bool traced = p.correction_w_sum > 0.0 && rng_next(p.rng) < rate;
        walk_radiance[base + 2u * local + 1u].w = traced ? p.correction_w_sum / rate : 0.0;
    }
#endif
}

void main()
{
    // One walk per invocation. (Measured on an H100: invocations that each ran ~16 walks in turn,
    // so that a lane whose walk ended early would start another, made the bake 5-8% slower.)
    if (gl_GlobalInvocationID.x < chunk_probes * directions)
        run_walk(gl_GlobalInvocationID.x);
}
