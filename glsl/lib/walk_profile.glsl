// Counters of a profiling build (WALK_PROFILE defined; off in normal builds, where every call
// here compiles to nothing): what each walk of the bake did, summed on the GPU for the benchmark.
// The tracking loops count their own iterations (lib/tracking.glsl: profile_flight_steps,
// profile_shadow_steps, profile_cell_steps); walk_profile_flush adds them to one of
// WALK_PROFILE_SLOTS rows of counters (rows spread the atomics; the host sums the rows in 64 bits).
#ifdef WALK_PROFILE
const uint WALK_PROFILE_SLOTS = 1024u;
layout(std430, binding = 5) buffer WalkProfile {
    // per row: walks finished, scattering events, free-flight steps, shadow-ray steps,
    // macrocell crossings, dispatches a walk ran in, the most events and the most tracking steps
    // one finished walk took (maxima, not sums: a small bake waits for its longest walk)
    uint walk_profile[];
};

void walk_profile_flush(int finished, int events)
{
    uint row = 8u * (gl_WorkGroupID.x % WALK_PROFILE_SLOTS);
    atomicAdd(walk_profile[row + 0u], uint(finished));
    atomicAdd(walk_profile[row + 1u], finished != 0 ? uint(events) : 0u);
    atomicAdd(walk_profile[row + 2u], profile_flight_steps);
    atomicAdd(walk_profile[row + 3u], profile_shadow_steps);
    atomicAdd(walk_profile[row + 4u], profile_cell_steps);
    atomicAdd(walk_profile[row + 5u], 1u);
    if (finished != 0) {
        atomicMax(walk_profile[row + 6u], uint(events));
        atomicMax(walk_profile[row + 7u], profile_flight_steps + profile_shadow_steps);
    }
}
#else
void walk_profile_flush(int finished, int events) {}
#endif
