// Free-flight sampling and transmittance against a majorant (Woodcock delta tracking and ratio
// tracking). Unbiased as long as majorant >= sigma_t. Every loop draws on a step budget, so a dense
// or pathological volume cannot hang the GPU; a path that runs out is dropped and counted in
// tracking_stats.truncated_paths (the renderers report it, the tests assert it is 0).

layout(std430, binding = 7) buffer TrackingStats
{
    uint truncated_paths;
    uint nonfinite_samples;
} tracking_stats;

const int TRACK_ESCAPED = 0;
const int TRACK_COLLIDED = 1;
const int TRACK_OUT_OF_STEPS = 2;

// Samples the distance to the next real collision on origin + t * direction, t in [t_min, t_max].
// When the steps run out, t_collision is where tracking stopped: free flight is memoryless, so a
// flight continued from there (same majorant) is distributed exactly as one never interrupted.
int delta_track(vec3 origin, vec3 direction, float t_min, float t_max, inout uint rng,
                inout int steps_left, out float t_collision)
{
    t_collision = t_max;
    if (majorant <= 0.0)
        return TRACK_ESCAPED;
    float t = t_min;
    while (steps_left > 0) {
        --steps_left;
        t -= log(1.0 - rng_next(rng)) / majorant;
        if (t >= t_max)
            return TRACK_ESCAPED;
        if (rng_next(rng) * majorant < sigma_t_at(origin + t * direction)) {
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
    if (majorant <= 0.0)
        return true;
    while (steps_left > 0) {
        --steps_left;
        t -= log(1.0 - rng_next(rng)) / majorant;
        if (t >= t_max)
            return true;
        transmittance *= max(0.0, 1.0 - sigma_t_at(origin + t * direction) / majorant);
        if (transmittance < 0.1) {
            float survive = transmittance * 10.0;
            if (rng_next(rng) >= survive) {
                transmittance = 0.0;
                return true;
            }
            transmittance = 0.1;
        }
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
