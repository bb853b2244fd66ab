// Free-flight sampling and transmittance against a majorant (Woodcock delta tracking and ratio
// tracking). Unbiased as long as majorant >= sigma_t. Every loop draws on a step budget, so a dense
// or pathological volume cannot hang the GPU; a path that runs out is dropped and counted in
// tracking_stats.truncated_paths (the renderers report it, the tests assert it is 0).
//
// Empty-space skipping (use_majorant_grid != 0, as in pbrt-v4): the box is cut into macrocells,
// each with its own majorant (glsl/majorant_grid.comp, app/twins/majorant_grid.py), and tracking walks the
// cells along the ray with a 3D DDA (Amanatides and Woo). In a cell of majorant m a free-flight
// distance is drawn with rate m; if it ends inside the cell, that is a tentative collision (real
// or null, as with one majorant); if not, the walk moves to the next cell and draws afresh there
// (exact: the exponential is memoryless). Cells of majorant 0 are crossed without a random
// number. With use_majorant_grid == 0 (or GLOBAL_MAJORANT defined) the one global majorant is
// used: the same estimators, slower where the medium is thin (for comparisons and the benchmark).
//
// Resumable either way: every loop iteration (a tentative collision or a cell crossing) takes one
// step from steps_left. Between iterations the whole state is the distance t reached (and the
// cell, a function of t), so when the steps run out the functions return t, and a later call from
// there (a fresh walk from that point) draws the same random numbers, in the same order, as the
// uninterrupted call would have.

layout(std430, binding = 7) buffer TrackingStats
{
    uint truncated_paths;
    uint nonfinite_samples;
} tracking_stats;

// Profiling build only (lib/walk_profile.glsl): loop iterations of this invocation.
#ifdef WALK_PROFILE
uint profile_flight_steps = 0u;   // delta-tracking iterations (tentative collisions, crossings)
uint profile_shadow_steps = 0u;   // ratio-tracking iterations
uint profile_cell_steps = 0u;     // macrocell crossings of either
#define PROFILE_COUNT(counter) counter += 1u
#else
#define PROFILE_COUNT(counter)
#endif

const int TRACK_ESCAPED = 0;
const int TRACK_COLLIDED = 1;
const int TRACK_OUT_OF_STEPS = 2;

// Russian roulette on a ratio-tracking estimate: below 0.1 it survives with probability
// 10 x transmittance and is then raised to 0.1 (unbiased). True when the estimate was ended.
#ifndef RATIO_ROULETTE_BELOW
#define RATIO_ROULETTE_BELOW 0.1
#endif
bool ratio_roulette(inout float transmittance, inout uint rng)
{
    if (transmittance >= RATIO_ROULETTE_BELOW)
        return false;
    if (rng_next(rng) >= transmittance / RATIO_ROULETTE_BELOW) {
        transmittance = 0.0;
        return true;
    }
    transmittance = RATIO_ROULETTE_BELOW;
    return false;
}

#include "lib/cell_walk.glsl"

// A tentative collision at x (majorant m) of a flight along d: real (true) or null. Delta
// tracking's own decision, real with probability sigma_t / m.
bool tracking_collides(vec3 x, vec3 d, float m, inout uint rng)
{
    return rng_next(rng) * m < sigma_t_at(x);
}

#if !defined(GLOBAL_MAJORANT)
// Starts a walk over the macrocells for t in [t, t_max] clipped to the box; m is the first cell's
// majorant. False when nothing of the range lies in the box (or all is vacuum).
//
// The grid's last faces are the box's. A point within CELL_WALK_SNAP of one (lib/cell_walk.glsl)
// counts as having reached it, so the walk leaves the grid there while the box still holds a
// sliver of medium up to t_end: that sliver keeps the last cell's majorant (it lies inside that
// cell, whose majorant bounds it) and is tracked like the rest. Ending the walk there instead
// skipped the sliver: a path tracer biased bright wherever sigma_t times the snap distance was not
// small (a fully opaque box, sigma_t = 1e4: +86% single scattering; tests/test_majorant_grid.py).
// Where the last cell's exit and the box's exit differ by float rounding only (a few ulps), the
// walk ends as it reaches the grid's last face: a resumed walk then takes the same steps as the
// uninterrupted one (tests/test_majorant_grid.py), and what that leaves out is a few ulps of path.
const float SLIVER_ROUNDING = 1e-6;

bool majorant_walk_begin(vec3 origin, vec3 direction, inout float t, float t_max,
                         out float t_end, out CellWalk w, out float m)
{
    float b0, b1;
    t_end = t_max;
    m = 0.0;
    if (majorant_grid_bound <= 0.0 || !box_intersect(origin, direction, b0, b1))
        return false;
    t = max(t, b0);
    t_end = min(t_max, b1);
    if (t >= t_end)
        return false;
    cell_walk_start(origin, direction, t, w);
    m = cell_majorant(w);                 // the cell holding the start (clamped into the grid)
    if (cell_walk_cross(w, t))
        m = cell_majorant(w);
    else if (!(t_end - t > SLIVER_ROUNDING * max(abs(t_end), 1.0)))
        return false;
    return true;
}

// Draws a free flight at the current cell's rate m from t; true (t moved there) when it ends
// before cell_end: a tentative collision. Cells with m = 0 draw nothing.
bool majorant_walk_sample(float m, inout float t, float cell_end, inout uint rng)
{
    if (m <= 0.0)
        return false;
    float t_try = t - log(1.0 - rng_next(rng)) / m;
    if (t_try >= cell_end)
        return false;
    t = t_try;
    return true;
}

// After a null collision at t (tentative) or a flight past the cell (not tentative): crosses the
// faces reached, if any, and loads the next cell's majorant. False once the ray has left the range.
// A walk that leaves the grid before t_end (within the snap of its last face) keeps the last
// cell's majorant m for the sliver left (see majorant_walk_begin).
bool majorant_walk_next(inout CellWalk w, inout float m, inout float t, float cell_end,
                        float t_end, bool tentative)
{
    if (tentative) {
        if (!any(cell_walk_faces_at(w, t)))
            return true;   // well inside the cell
    } else {
        t = max(t, cell_end);
        if (t >= t_end)
            return false;
    }
    if (!cell_walk_cross(w, t))
        return t_end - t > SLIVER_ROUNDING * max(abs(t_end), 1.0);
    m = cell_majorant(w);
    return true;
}

// delta_track with the macrocell majorants (same contract).
int delta_track_grid(vec3 origin, vec3 direction, float t_min, float t_max, inout uint rng,
                     inout int steps_left, out float t_collision)
{
    t_collision = t_max;
    float t = t_min, t_end, m;
    CellWalk w;
    if (!majorant_walk_begin(origin, direction, t, t_max, t_end, w, m))
        return TRACK_ESCAPED;
    CHECK_LOOP_COUNTER(crossings);   // a straight ray crosses at most the grid's three sides
    while (steps_left > 0) {
        --steps_left;
        PROFILE_COUNT(profile_flight_steps);
        float cell_end = min(cell_walk_exit(w), t_end);
        bool tentative = majorant_walk_sample(m, t, cell_end, rng);
        if (!tentative)
            PROFILE_COUNT(profile_cell_steps);
        if (!tentative)
            CHECK_LOOP(crossings, w.cells.x + w.cells.y + w.cells.z + 3, CHECK_SITE_CELL_LOOP);
        if (tentative && tracking_collides(origin + t * direction, direction, m, rng)) {
            t_collision = t;
            return TRACK_COLLIDED;
        }
        if (!majorant_walk_next(w, m, t, cell_end, t_end, tentative))
            return TRACK_ESCAPED;
    }
    t_collision = t;
    return TRACK_OUT_OF_STEPS;
}

// ratio_track_continue with the macrocell majorants (same contract).
bool ratio_track_continue_grid(vec3 origin, vec3 direction, inout float t, float t_max,
                               inout float transmittance, inout uint rng, inout int steps_left)
{
    float t_end, m;
    CellWalk w;
    if (!majorant_walk_begin(origin, direction, t, t_max, t_end, w, m))
        return true;
    CHECK_LOOP_COUNTER(crossings);   // a straight ray crosses at most the grid's three sides
    while (steps_left > 0) {
        --steps_left;
        PROFILE_COUNT(profile_shadow_steps);
        float cell_end = min(cell_walk_exit(w), t_end);
        bool tentative = majorant_walk_sample(m, t, cell_end, rng);
        if (!tentative)
            PROFILE_COUNT(profile_cell_steps);
        if (!tentative)
            CHECK_LOOP(crossings, w.cells.x + w.cells.y + w.cells.z + 3, CHECK_SITE_CELL_LOOP);
        if (tentative) {
            transmittance *= max(0.0, 1.0 - sigma_t_at(origin + t * direction) / m);
            if (ratio_roulette(transmittance, rng))
                return true;
        }
        if (!majorant_walk_next(w, m, t, cell_end, t_end, tentative))
            return true;
    }
    return false;
}
#endif

// Samples the distance to the next real collision on origin + t * direction, t in [t_min, t_max].
// When the steps run out, t_collision is where tracking stopped: free flight is memoryless, so a
// flight continued from there (same majorant) is distributed exactly as one never interrupted.
int delta_track(vec3 origin, vec3 direction, float t_min, float t_max, inout uint rng,
                inout int steps_left, out float t_collision)
{
#if !defined(GLOBAL_MAJORANT)
    if (use_majorant_grid != 0)
        return delta_track_grid(origin, direction, t_min, t_max, rng, steps_left, t_collision);
#endif
    t_collision = t_max;
    if (majorant <= 0.0)
        return TRACK_ESCAPED;
    float t = t_min;
    while (steps_left > 0) {
        --steps_left;
        PROFILE_COUNT(profile_flight_steps);
        t -= log(1.0 - rng_next(rng)) / majorant;
        if (t >= t_max)
            return TRACK_ESCAPED;
        if (tracking_collides(origin + t * direction, direction, majorant, rng)) {
            t_collision = t;
            return TRACK_COLLIDED;
        }
    }
    t_collision = t;
    return TRACK_OUT_OF_STEPS;
}

// Unbiased transmittance estimate along origin + t * direction up to t_max (ratio tracking),
// resumable: t and transmittance carry the progress (start with t = t_min, transmittance = 1).
// Russian roulette ends low estimates early without bias. Returns true when the estimate is
// complete; false when the step budget ran out first, and a later call with the same t and
// transmittance continues it exactly as if never interrupted (null collisions are memoryless).
bool ratio_track_continue(vec3 origin, vec3 direction, inout float t, float t_max,
                          inout float transmittance, inout uint rng, inout int steps_left)
{
#if !defined(GLOBAL_MAJORANT)
    if (use_majorant_grid != 0)
        return ratio_track_continue_grid(origin, direction, t, t_max, transmittance, rng,
                                         steps_left);
#endif
    if (majorant <= 0.0)
        return true;
    while (steps_left > 0) {
        --steps_left;
        PROFILE_COUNT(profile_shadow_steps);
        t -= log(1.0 - rng_next(rng)) / majorant;
        if (t >= t_max)
            return true;
        transmittance *= max(0.0, 1.0 - sigma_t_at(origin + t * direction) / majorant);
        if (ratio_roulette(transmittance, rng))
            return true;
    }
    return false;
}

// Unbiased transmittance estimate along origin + t * direction, t in [t_min, t_max], or -1 when the
// step budget ran out.
float ratio_track(vec3 origin, vec3 direction, float t_min, float t_max, inout uint rng,
                  inout int steps_left)
{
    float t = t_min, transmittance = 1.0;
    return ratio_track_continue(origin, direction, t, t_max, transmittance, rng, steps_left)
        ? transmittance : -1.0;
}

// Transmittance from p to the box boundary along direction (a shadow ray), resumable like
// ratio_track_continue: start with t < 0 (not begun) and transmittance 1.
bool transmittance_to_boundary_continue(vec3 p, vec3 direction, inout float t,
                                        inout float transmittance, inout uint rng,
                                        inout int steps_left)
{
    float t0, t1;
    if (!box_intersect(p, direction, t0, t1))
        return true;
    if (t < 0.0)
        t = t0;
    return ratio_track_continue(p, direction, t, t1, transmittance, rng, steps_left);
}

// Transmittance from p to the box boundary along direction (a shadow ray), or -1 if out of steps.
float transmittance_to_boundary(vec3 p, vec3 direction, inout uint rng, inout int steps_left)
{
    float t = -1.0, transmittance = 1.0;
    return transmittance_to_boundary_continue(p, direction, t, transmittance, rng, steps_left)
        ? transmittance : -1.0;
}
