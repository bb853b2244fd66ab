// Deterministic transmittance towards the sun: midpoint quadrature of sigma_t from x to the box
// boundary, at most 4096 steps (exp(-tau) is 0 in float32 past tau = 104, so it stops there).
// The probes' own sun (probe_sun.comp); the light grid marches whole sun rays instead
// (light_transmittance.comp). (A jump over empty macrocells was measured and removed:
// bench/h100-lost-context, docs/experiments.md.)

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
    for (int i = 0; i < n && tau < 104.0; ++i)
        tau += sigma_t_at(x + (t0 + (float(i) + 0.5) * dt) * sun_direction) * dt;
    return tau;
}

float sun_transmittance_march(vec3 x)
{
    return exp(-sun_optical_depth_march(x));
}
