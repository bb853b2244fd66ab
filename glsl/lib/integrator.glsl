// Volumetric path tracing: the radiance arriving at `origin` from the direction -direction, i.e.
// carried by light that travels towards origin along -direction. Full multiple scattering, at most
// max_bounces scattering events, next-event estimation towards the sun with ratio tracking,
// environment for paths that leave the box, throughput-based Russian roulette.
// The probe bake calls this too: a walk starts at the probe and continues from each scattering
// point. Directly seen sunlight (a delta) never enters; only scattered sun and the environment do.
uniform int max_bounces;
uniform float anisotropy;  // Henyey-Greenstein g

#ifndef RR_START_BOUNCE
#define RR_START_BOUNCE 3
#endif

// Returns false when the path ran out of its step budget (its estimate is then discarded).
bool path_radiance(vec3 origin, vec3 direction, inout uint rng, out vec3 radiance)
{
    radiance = vec3(0.0);
    vec3 throughput = vec3(1.0);
    int steps_left = MAX_PATH_STEPS;
    vec3 x = origin;
    vec3 w = direction;
    for (int bounce = 0; ; ++bounce) {
        float t0, t1;
        if (!box_intersect(x, w, t0, t1)) {
            radiance += throughput * environment;
            return true;
        }
        float t;
        int event = delta_track(x, w, t0, t1, rng, steps_left, t);
        if (event == TRACK_ESCAPED) {
            radiance += throughput * environment;
            return true;
        }
        if (event == TRACK_OUT_OF_STEPS)
            return false;
        if (bounce >= max_bounces)
            return true;  // this would be scattering event bounce + 1 > max_bounces
        x += t * w;
        throughput *= albedo_at(x);
        if (all(equal(throughput, vec3(0.0))))
            return true;
        // Next-event estimation towards the sun.
        if (any(greaterThan(sun_irradiance, vec3(0.0)))) {
            float tr = transmittance_to_boundary(x, sun_direction, rng, steps_left);
            if (tr < 0.0)
                return false;
            radiance += throughput * sun_irradiance * (tr * phase_hg(dot(sun_direction, w), anisotropy));
        }
        w = sample_hg(w, anisotropy, rng_next(rng), rng_next(rng));
        if (bounce + 1 >= RR_START_BOUNCE) {
            float q = max(throughput.r, max(throughput.g, throughput.b));
            if (q < 1.0) {
                if (rng_next(rng) >= q)
                    return true;
                throughput /= q;
            }
        }
    }
}

// Adds one sample to a running sum unless it is not finite (then it is counted, never averaged).
void accumulate_sample(inout vec3 sum, inout uint count, vec3 value, bool valid)
{
    if (!valid) {
        atomicAdd(tracking_stats.truncated_paths, 1u);
        return;
    }
    if (any(isnan(value)) || any(isinf(value))) {
        atomicAdd(tracking_stats.nonfinite_samples, 1u);
        return;
    }
    sum += value;
    count += 1u;
}
