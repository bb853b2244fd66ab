// The checking build (SHADER_CHECKS defined; app/gl/checks.py): bounds checks on buffer, image and
// texel indices, and caps on loops, that count every hit per site in a buffer the host reads (and
// tests require to stay 0: tests/test_battery.py runs every method and the bake over the stress
// battery with it). Without SHADER_CHECKS every macro here is empty: the normal build is the same
// code as before the checks.
//
// A hit is counted, and the access it guards is not clamped: the checking build reports what the
// normal build would do, it does not hide it. A loop cap breaks the loop (the normal build has no
// cap there; a hit means the loop ran longer than any scene should make it).
//
// Sites: CHECK_SITE_* below; app/gl/checks.py reads their names from this file.
#define CHECK_SITE_TRANSFER_ENTRY 1      // lib/medium.glsl: transfer table entry index
#define CHECK_SITE_MAJORANT_CELL 2       // lib/cell_walk.glsl: macrocell texel fetch
#define CHECK_SITE_PROBE_INDEX 3         // probe accumulators (probes[], prior[])
#define CHECK_SITE_WALK_INDEX 4          // walk buffers (walks[], walk_radiance[])
#define CHECK_SITE_PATH_INDEX 5          // the path tracer's per-pixel states
#define CHECK_SITE_IMAGE_TEXEL 6         // imageStore / imageLoad coordinates
#define CHECK_SITE_NOISE_INDEX 7         // adaptive walks' budgets (walk_passes[])
#define CHECK_SITE_SEGMENT_INDEX 8       // the light grid's segment sums
#define CHECK_SITE_ENVIRONMENT_INDEX 9   // environment map rows, columns and CDFs
#define CHECK_SITE_CELL_LOOP 10          // macrocell walks (DDA) past the grid's cells
#define CHECK_SITE_MARCH_LOOP 11         // raymarch and shadow-march loops past their caps
#define CHECK_SITE_TRACKING_LOOP 12      // tracking loops past the path's step budget
#define CHECK_SITE_WALK_BUDGET 13        // a probe's walk budget out of [1, passes]
#define CHECK_SITE_PAGE_MISS 14          // lib/brick_pool.glsl: a brick's slot holds another brick
#define CHECK_SITE_COUNT 16

#if defined(SHADER_CHECKS)
#ifndef SHADER_CHECKS_BINDING
#define SHADER_CHECKS_BINDING 9
#endif
layout(std430, binding = SHADER_CHECKS_BINDING) buffer ShaderChecks {
    uint shader_check_hits[CHECK_SITE_COUNT];
};
// index in [0, size)
#define CHECK_INDEX(index, size, site) \
    if (int(index) < 0 || uint(index) >= uint(size)) atomicAdd(shader_check_hits[site], 1u)
// integer texel coordinates in [0, size) per axis (ivec2 or ivec3 both)
#define CHECK_TEXEL(coord, size, site) \
    if (any(lessThan(coord, coord * 0)) || any(greaterThanEqual(coord, size))) \
        atomicAdd(shader_check_hits[site], 1u)
// a condition that must hold
#define CHECK_TRUE(condition, site) \
    if (!(condition)) atomicAdd(shader_check_hits[site], 1u)
// a loop's counter: declare it before the loop, count at the top of each iteration
#define CHECK_LOOP_COUNTER(name) int name = 0
#define CHECK_LOOP(name, cap, site) \
    if (++name > int(cap)) { atomicAdd(shader_check_hits[site], 1u); break; }
#else
#define CHECK_INDEX(index, size, site)
#define CHECK_TEXEL(coord, size, site)
#define CHECK_TRUE(condition, site)
#define CHECK_LOOP_COUNTER(name)
#define CHECK_LOOP(name, cap, site)
#endif
