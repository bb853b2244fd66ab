// The sun's shadow ray: its transmittance from a point to the box boundary towards the sun,
// unbiased, resumable like transmittance_to_boundary_continue (start with t < 0, transmittance 1;
// true when done, false when the step budget ran out first). One place for every pass that traces
// it: the path tracer, `probes` and `guided` (lib/integrator.glsl) and the bake's walks and their
// sun correction (glsl/probe_walks.comp, glsl/probe_sun_correction.comp).
//
// SHADOW_TRACKING_RESIDUAL undefined: ratio tracking (lib/tracking.glsl), as before.
//
// SHADOW_TRACKING_RESIDUAL defined: residual ratio tracking (Novak, Selle, Jarosz 2014) with the
// light grid's optical depth (lib/light_grid.glsl, the sun's optical depth from a point to the
// box, baked once per scene) as the control. The ray, t in [t0, t1] in the box, is cut at the
// lattice t0 + k h (h = shadow_control_step, world units) and at the macrocells' faces. On lattice
// segment k the control extinction is the grid's optical depth lost over it,
//     c_k = (tau_grid(t_k) - tau_grid(t_k+1)) / (t_k+1 - t_k)     (tau_grid(t1) = 0),
// clamped in each macrocell to [0, m], m the cell's majorant (0 in an empty cell). The estimate is
//     T = exp(-sum over pieces of c * length) * product over tentative collisions of
//         (1 - (sigma_t - c) / m),
// the collisions drawn at rate m exactly as ratio tracking draws them (the same count, cost alike
// but for one grid read a lattice node). Whatever c is, E[product] = exp(-integral of
// (sigma_t - c)) (the Poisson process's generating function: it holds for any real c), so T is
// unbiased for ANY control: the grid may be coarse, stale or wrong (tests/test_sun_shadow.py: x10
// and x0). With c in [0, m] and 0 <= sigma_t <= m each factor lies in [c / m, 1 + c / m], within
// [0, 2]: never negative. Where the grid follows the medium, sigma_t - c is small and the factors
// stay near 1: the noise of ratio tracking's 1 - sigma_t / m is gone. The control's factor is
// applied as t advances (at each collision and piece end), so the estimate so far always covers
// [t0, t], and a resumed ray (t kept) recomputes the same lattice: it continues exactly.
// Russian roulette compares the estimate with what the grid predicts up to the current segment's
// start, P = exp(-(tau_grid(t0) - tau_grid(t_k))): below 0.1 P it survives with probability
// T / (0.1 P) and is raised to 0.1 P (unbiased for any P: a function of the ray's state). Ratio
// tracking's roulette on T alone made nearly every estimate where T < 0.1 a coin flip between 0
// and 0.1, which is most of the ratio-tracked ray's noise in a shadow; this one ends only those
// whose collisions took them well below the grid's prediction. NumPy twin: app/twins/sun_shadow.py.
//
// Includes are expanded once, where first met, #if or not (app/gl/shaders.py): a shader that
// includes lib/light_grid.glsl inside an #if block must include it (or this file) unconditionally
// before that block, or a build without the block loses it here.
#include "lib/light_grid.glsl"
#if defined(SHADOW_TRACKING_RESIDUAL)

uniform float shadow_control_step;   // h, world units (> 0): the control's lattice spacing

// The grid's optical depth at ray distance t (0 at the box's exit t1: the control's end).
float shadow_control_depth(vec3 origin, float t, float t1)
{
    return t >= t1 ? 0.0 : max(light_grid_optical_depth(origin + t * sun_direction), 0.0);
}

// The control's lattice: segment k spans [t0 + k h, min(t0 + (k + 1) h, t1)], tau_b the grid's
// depth at its end, c its control extinction (unclamped). Its ends are always computed as
// t0 + k h, so a resumed ray meets the same nodes.
struct ShadowControl {
    float k, t_b, tau_b, c;
    float tau_a;   // the grid's depth at the segment's start (the roulette's prediction)
};

void shadow_control_set(vec3 origin, float t0, float t1, float k, float tau_a,
                        inout ShadowControl s)
{
    float h = shadow_control_step;
    float t_a = min(t0 + k * h, t1);
    s.k = k;
    s.tau_a = tau_a;
    s.t_b = min(t0 + (k + 1.0) * h, t1);
    s.tau_b = shadow_control_depth(origin, s.t_b, t1);
    s.c = s.t_b > t_a ? (tau_a - s.tau_b) / (s.t_b - t_a) : 0.0;
}

// The segment holding t (a node counts as its next segment's start): two grid reads.
void shadow_control_at(vec3 origin, float t, float t0, float t1, out ShadowControl s)
{
    float k = max(floor((t - t0) / shadow_control_step), 0.0);
    if (t0 + (k + 1.0) * shadow_control_step <= t)   // rounding put t's node one segment early
        k += 1.0;
    shadow_control_set(origin, t0, t1, k,
                       shadow_control_depth(origin, min(t0 + k * shadow_control_step, t1), t1), s);
}

bool sun_transmittance_continue(vec3 origin, inout float t, inout float transmittance,
                                inout uint rng, inout int steps_left)
{
    vec3 d = sun_direction;
    float t0, t1;
    if (!box_intersect(origin, d, t0, t1))
        return true;
    if (t < 0.0)
        t = t0;
    float t_end, m;
    bool grid = false;
#if !defined(GLOBAL_MAJORANT)
    CellWalk w;
    if (use_majorant_grid != 0) {
        grid = true;
        if (!majorant_walk_begin(origin, d, t, t1, t_end, w, m))
            return true;
    }
#endif
    if (!grid) {
        m = majorant;
        t_end = t1;
        if (m <= 0.0 || t >= t_end)
            return true;
    }
    ShadowControl s;
    shadow_control_at(origin, t, t0, t1, s);
    float tau_start = shadow_control_depth(origin, t0, t1);   // the roulette's reference
    CHECK_LOOP_COUNTER(crossings);
    while (steps_left > 0) {
        --steps_left;
        PROFILE_COUNT(profile_shadow_steps);
        float cell_end = t_end;
#if !defined(GLOBAL_MAJORANT)
        if (grid)
            cell_end = min(cell_walk_exit(w), t_end);
#endif
        // an empty cell is crossed whole with control 0 (no grid read, no random number)
        bool empty = m <= 0.0;
        float piece_end = empty ? cell_end : min(cell_end, s.t_b);
        float c = clamp(s.c, 0.0, max(m, 0.0));
        float t_from = t;
        bool tentative = majorant_walk_sample(m, t, piece_end, rng);
        transmittance *= exp(-c * ((tentative ? t : piece_end) - t_from));
        if (tentative) {
            transmittance *= max(0.0, 1.0 - (sigma_t_at(origin + t * d) - c) / m);
            float below = RATIO_ROULETTE_BELOW * exp(-max(tau_start - s.tau_a, 0.0));
            if (transmittance < below) {
                if (rng_next(rng) * below >= transmittance) {
                    transmittance = 0.0;
                    return true;
                }
                transmittance = below;
            }
#if !defined(GLOBAL_MAJORANT)
            if (grid && !majorant_walk_next(w, m, t, cell_end, t_end, true))
                return true;
#endif
            continue;
        }
        t = piece_end;
        if (t >= t_end)
            return true;
#if !defined(GLOBAL_MAJORANT)
        if (grid && t >= cell_end) {
            PROFILE_COUNT(profile_cell_steps);
            CHECK_LOOP(crossings, w.cells.x + w.cells.y + w.cells.z + 3, CHECK_SITE_CELL_LOOP);
            if (!majorant_walk_next(w, m, t, cell_end, t_end, false))
                return true;
        }
#endif
        if (empty)                 // past any number of nodes: find the segment again
            shadow_control_at(origin, t, t0, t1, s);
        else if (t >= s.t_b)       // the next segment: one grid read
            shadow_control_set(origin, t0, t1, s.k + 1.0, s.tau_b, s);
    }
    return false;
}
#else
bool sun_transmittance_continue(vec3 origin, inout float t, inout float transmittance,
                                inout uint rng, inout int steps_left)
{
    return transmittance_to_boundary_continue(origin, sun_direction, t, transmittance, rng,
                                              steps_left);
}
#endif

// The sun's transmittance from p, or -1 if the step budget ran out.
float sun_transmittance(vec3 p, inout uint rng, inout int steps_left)
{
    float t = -1.0, transmittance = 1.0;
    return sun_transmittance_continue(p, t, transmittance, rng, steps_left) ? transmittance : -1.0;
}
