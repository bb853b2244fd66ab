// Deterministic transmittance towards the sun: midpoint quadrature of sigma_t from x to the box
// boundary, at most 4096 steps (exp(-tau) is 0 in float32 past tau = 104, so it stops there).
// The probes' own sun (probe_sun.comp); the light grid marches whole sun rays instead
// (light_transmittance.comp).
// With SUN_MARCH_SKIPS_EMPTY_CELLS and the majorant grid (use_majorant_grid != 0) the quadrature
// points in macrocells of majorant 0 are jumped over instead of sampled: sigma_t is 0 there, so the
// sum is the same, over the same points (app/twins/shadow_march.py has no grid and must agree).
// This jump was taken out after the bake benchmark lost the H100's context with it in place
// (commit 03404d4); it is back under this define, with the checking build's caps on both of its
// loops, while that loss is investigated (app/rendering/probes.py SUN_MARCH_SKIPS_EMPTY_CELLS).
#include "lib/cell_walk.glsl"

uniform float march_step;  // world units between quadrature points

// Optical depth towards the sun (stops once past 104, where the transmittance is 0 in float32).
float sun_optical_depth_march(vec3 x)
{
    float t0, t1;
    if (!box_intersect(x, sun_direction, t0, t1))
        return 0.0;
    int n = clamp(int(ceil((t1 - t0) / march_step)), 1, 4096);
    float dt = (t1 - t0) / float(n);
    float tau = 0.0;
#if defined(SUN_MARCH_SKIPS_EMPTY_CELLS) && !defined(GLOBAL_MAJORANT)
    if (use_majorant_grid != 0) {
        if (majorant_grid_bound <= 0.0)
            return 0.0;   // the whole volume is vacuum
        CellWalk w;
        bool in_grid = cell_walk_begin(x, sun_direction, t0, w);
        int i = 0;
        CHECK_LOOP_COUNTER(points);
        CHECK_LOOP_COUNTER(crossings);
        while (i < n && tau < 104.0) {
            CHECK_LOOP(points, n, CHECK_SITE_MARCH_LOOP);
            float t = t0 + (float(i) + 0.5) * dt;
            while (in_grid && cell_walk_exit(w) <= t) {
                CHECK_LOOP(crossings, w.cells.x + w.cells.y + w.cells.z + 3, CHECK_SITE_CELL_LOOP);
                in_grid = cell_walk_cross(w, cell_walk_exit(w));
            }
            if (in_grid && cell_majorant(w) <= 0.0) {
                // the first point past this empty cell's exit
                int next = int(ceil((cell_walk_exit(w) - t0) / dt - 0.5));
                CHECK_TRUE(next >= 0, CHECK_SITE_MARCH_LOOP);
                i = max(i + 1, next);
                continue;
            }
            tau += sigma_t_at(x + t * sun_direction) * dt;
            ++i;
        }
        return tau;
    }
#endif
    for (int i = 0; i < n && tau < 104.0; ++i)
        tau += sigma_t_at(x + (t0 + (float(i) + 0.5) * dt) * sun_direction) * dt;
    return tau;
}

float sun_transmittance_march(vec3 x)
{
    return exp(-sun_optical_depth_march(x));
}
