// `guided`'s level 0 (app/rendering/renderer.py, RenderSettings.guided_*): an unbiased estimate of
// what the probes predict a camera ray sees,
//   F = integral over the ray of T(t) sigma_s(t) S(x(t), d) dt + T(t_exit) L_env(d),
//   S(x, d) = the probes' inscattered radiance (lib/probes.glsl probe_inscattered)
//             + sun * T_grid(x) * phase(d . sun)   (the sun from the light grid),
// with T the camera ray's transmittance. `guided`'s level 1 (lib/integrator.glsl
// GUIDED_RESIDUAL) is a path-traced sample minus a single-collision estimate of the same F on the
// same random numbers, so level 0 + level 1 has the path tracer's mean whatever the probes hold:
// level 0 only has to be unbiased for F, and as smooth as it can be.
//
// The ray is cut into the raymarcher's segments [t0 + i dt, t0 + (i + 1) dt], each with the
// extinction at its jittered point x_i, sigma_i. The camera ray's transmittance up to any point is
// residual ratio tracking with that piecewise-constant sigma_i as its control: T = exp(-tau_c) W,
// tau_c the control's optical depth (exact) and W the product over null collisions (at the
// macrocell majorant m) of 1 - (sigma_t - sigma_i) / m, whose mean is exp(-(tau - tau_c)) for any
// control (Novak et al. 2014's residual ratio tracking). Where the quadrature is close, the factors
// are close to 1 and T nearly noiseless; plain ratio tracking's factors 1 - sigma_t / m made level 0
// as noisy as level 1 on the foot (llvmpipe, 32^2). Per segment:
//   - thin (the macrocell majorant at its ends times dt at most 1): T(x_i) sigma_s(x_i) S(x_i) dt
//     at the segment's jittered point (stratified: unbiased for the segment's integral);
//   - thick: T(segment start) times a delta-tracking collision estimate within the segment
//     (albedo S at the collision, 0 if the flight leaves it), unbiased for the integral over the
//     segment of T(start, t) sigma_s S dt, and far less noisy than a point where the medium's lit
//     skin is thinner than the segment (a point there sees either nothing or sigma_t dt times too
//     much).
// The choices depend only on the majorant grid and the jitter, never on the tracking's random
// numbers, so the estimate stays unbiased. The collision flights use the global majorant (it bounds
// sigma_t in any segment). The control is 0 in empty macrocells, where sigma_t is 0 too.
#include "lib/tracking.glsl"
#include "lib/guided_source.glsl"

uniform int guided_level0_budget;   // tracking steps one ray may take (a GPU: no driver limit)

float guided_segment_majorant(vec3 a, vec3 b)
{
#if !defined(GLOBAL_MAJORANT)
    if (use_majorant_grid != 0) {
        ivec3 cells = textureSize(majorant_grid, 0);
        vec3 per = vec3(cells) / (2.0 * box_half_extent);
        ivec3 ca = clamp(ivec3(floor((a + box_half_extent) * per)), ivec3(0), cells - 1);
        ivec3 cb = clamp(ivec3(floor((b + box_half_extent) * per)), ivec3(0), cells - 1);
        return max(texelFetch(majorant_grid, ca, 0).r, texelFetch(majorant_grid, cb, 0).r);
    }
#endif
    return majorant;
}

// Residual ratio tracking over [ta, tb] along the ray with control extinction sigma_c (see
// above): adds the control's optical depth to tau_c, multiplies w by the null collisions' factors.
// False when the step budget ran out.
bool residual_track(vec3 origin, vec3 d, float ta, float tb, float sigma_c, inout float tau_c,
                    inout float w, inout uint rng, inout int steps)
{
    if (tb <= ta)
        return true;
#if !defined(GLOBAL_MAJORANT)
    if (use_majorant_grid != 0) {
        float t = ta, t_end, m;
        CellWalk walk;
        if (!majorant_walk_begin(origin, d, t, tb, t_end, walk, m))
            return true;   // vacuum or outside the box: the control is 0 there too
        for (;;) {
            float c1 = min(cell_walk_exit(walk), t_end);
            if (m > 0.0) {
                tau_c += sigma_c * (c1 - t);
                float s = t;
                for (;;) {
                    if (--steps <= 0)
                        return false;
                    s -= log(1.0 - rng_next(rng)) / m;
                    if (s >= c1)
                        break;
                    w *= 1.0 - (sigma_t_at(origin + s * d) - sigma_c) / m;
                }
            }
            if (c1 >= t_end || --steps <= 0)
                return steps > 0;
            t = c1;
            if (cell_walk_cross(walk, t))
                m = cell_majorant(walk);
            else if (!(t_end - t > SLIVER_ROUNDING * max(abs(t_end), 1.0)))
                return true;   // (the sliver past the grid's last face keeps m, as in tracking)
        }
    }
#endif
    float b0, b1;
    if (majorant <= 0.0 || !box_intersect(origin, d, b0, b1))
        return true;
    float t = max(ta, b0), t_end = min(tb, b1);
    if (t >= t_end)
        return true;
    tau_c += sigma_c * (t_end - t);
    for (;;) {
        if (--steps <= 0)
            return false;
        t -= log(1.0 - rng_next(rng)) / majorant;
        if (t >= t_end)
            return true;
        w *= 1.0 - (sigma_t_at(origin + t * d) - sigma_c) / majorant;
    }
}

// Russian roulette on the transmittance estimate exp(-tau_c) w: below 0.01 it survives with
// probability 100 times it and is raised to 0.01 (unbiased). False when it was ended.
bool level0_roulette(float tau_c, inout float w, inout uint rng)
{
    float t = exp(-tau_c) * w;
    if (t >= 0.01)
        return true;
    if (t <= 0.0 || rng_next(rng) >= t * 100.0) {
        w = 0.0;
        return false;
    }
    w = 0.01 / max(exp(-tau_c), 1e-30);
    return true;
}

vec3 guided_level0_radiance(vec3 origin, vec3 d, inout uint rng)
{
#if defined(ENVIRONMENT_MAP)
    vec3 background = environment_radiance(d);
#else
    vec3 background = environment;
#endif
    float t0, t1;
    if (!box_intersect(origin, d, t0, t1))
        return background;
    int n = clamp(int(ceil((t1 - t0) / raymarch_step)), 1, 8192);
    float dt = (t1 - t0) / float(n);
    float jitter = rng_next(rng);
    float scatter_allowed = max_bounces > 0 ? 1.0 : 0.0;
    float sun_phase = phase_hg(dot(sun_direction, d), anisotropy);
    float tau_c = 0.0, w = 1.0;   // the transmittance estimate up to where tracked: exp(-tau_c) w
    int steps = guided_level0_budget;
    bool ok = true;
    vec3 radiance = vec3(0.0);
    // Each segment's tracking pieces and its one scored point go through one call site each
    // (residual_track, guided_predicted_source): inlined at every call, four tracking calls and
    // two source fetches made this pass take 2.4-3.2 s to compile on the H200 with the driver's
    // cache empty (lab/experiments/compile_pragmas.py). The random numbers are drawn in the order
    // they were, and each score is weighted by the transmittance estimate where it was scored.
    for (int i = 0; i < n && ok && w != 0.0; ++i) {
        float ta = t0 + float(i) * dt;
        float tb = ta + dt;
        float t = ta + jitter * dt;
        vec3 x = origin + t * d;
        vec4 tf = classified_at(x);
        float sigma_i = density_scale * tf.a;
        float m = guided_segment_majorant(origin + ta * d, origin + tb * d);
        // up to two pieces tracked with control sigma_c: [ta, t_mid] then [t_mid, t_end]
        float sigma_c = sigma_i, t_mid = tb, t_end = tb;
        int pieces = 1;
        bool score_after_first = false;   // thin: the point at t, scored between the pieces
        bool scored = false;              // thick: a collision found by the flight
        vec3 score_x = x, score_rgb = tf.rgb;
        float score_weight = 0.0;         // transmittance estimate times its own factor
        bool roulette = true;             // (not after an empty stretch, as before)
        if (m <= 0.0 && sigma_i <= 0.0) {
            // Empty here: jump to the last sample before this macrocell's exit, as the raymarcher
            // does, tracking everything in between (exact: any medium there still counts).
            int last = empty_space_last_index(origin, d, t, i, t0, dt, jitter);
            sigma_c = 0.0;
            t_mid = t0 + float(last + 1) * dt;
            i = last;
            roulette = false;
        } else if (m * dt <= 1.0) {
            t_mid = t;
            pieces = 2;
            score_after_first = sigma_i > 0.0;
        } else {
            float s = ta;
            for (; steps > 0; --steps) {
                s -= log(1.0 - rng_next(rng)) / majorant;
                if (s >= tb)
                    break;
                vec3 xs = origin + s * d;
                vec4 ts = classified_at(xs);
                if (rng_next(rng) * majorant < density_scale * ts.a) {
                    scored = true;
                    score_x = xs;
                    score_rgb = ts.rgb;
                    score_weight = exp(-tau_c) * w;
                    break;
                }
            }
            ok = steps > 0;
        }
        for (int piece = 0; piece < pieces && ok; ++piece) {
            float a = piece == 0 ? ta : t_mid;
            float b = piece == 0 ? t_mid : t_end;
            ok = residual_track(origin, d, a, b, sigma_c, tau_c, w, rng, steps);
            if (ok && piece == 0 && score_after_first) {
                scored = true;
                score_weight = (exp(-tau_c) * w) * (sigma_i * dt);
            }
        }
        if (scored)
            radiance += score_weight * albedo * score_rgb
                        * guided_predicted_source(score_x, d, sun_phase);
        if (ok && roulette)
            level0_roulette(tau_c, w, rng);
    }
    if (!ok) {
        atomicAdd(tracking_stats.truncated_paths, 1u);   // out of steps: said in the stats
        return scatter_allowed * radiance;
    }
    return scatter_allowed * radiance + (exp(-tau_c) * w) * background;
}
