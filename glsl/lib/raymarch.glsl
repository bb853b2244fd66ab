// The raymarcher (the design card's): deterministic front-to-back marching with a jittered start.
// Each step of length dt at x adds transmittance * (1 - exp(-sigma_t dt)) * albedo(x) *
// [sun * T_sun(x) * phase + probe radiance convolved with the phase function]; T_sun comes from the
// baked light-transmittance texture (light_transmittance.comp). The step's opacity is integrated
// exactly for piecewise-constant sigma_t, so large steps through dense media stay bounded.
// Shared by raymarch.comp and raymarch.frag; each calls raymarch_pixel for its pixel. With
// ENVIRONMENT_MAP the environment behind the volume is the map's radiance along the ray.
uniform float raymarch_step;            // world units
uniform uint frame_index;               // keys the jitter; frames accumulate into a running mean
uniform uint seed;

layout(rgba32f, binding = 0) uniform image2D accumulation;  // rgb: running mean, a: frames

vec3 raymarch_radiance(vec3 origin, vec3 d, float jitter)
{
#if defined(ENVIRONMENT_MAP)
    vec3 environment = environment_radiance(d);   // the background this ray sees
#endif
    float t0, t1;
    if (!box_intersect(origin, d, t0, t1))
        return environment;
    int n = clamp(int(ceil((t1 - t0) / raymarch_step)), 1, 8192);
    float dt = (t1 - t0) / float(n);
    float transmittance = 1.0;
    vec3 radiance = vec3(0.0);
    float scatter_allowed = max_bounces > 0 ? 1.0 : 0.0;
    float sun_phase = phase_hg(dot(sun_direction, d), anisotropy);
    for (int i = 0; i < n && transmittance > 1e-6; ++i) {
        vec3 x = origin + (t0 + (float(i) + jitter) * dt) * d;
        vec4 tf = transfer_at(density_at(x));
        float sigma_t = density_scale * tf.a;
        if (sigma_t <= 0.0)
            continue;
        float opacity = 1.0 - exp(-sigma_t * dt);
        float probe_sun;
        vec3 inscattered = probe_inscattered(x, d, probe_sun);
        float sun_t = light_grid_transmittance(x);
        vec3 source = albedo * tf.rgb * (inscattered + sun_irradiance * (sun_t * sun_phase));
        radiance += transmittance * opacity * scatter_allowed * source;
        transmittance *= 1.0 - opacity;
    }
    return radiance + transmittance * environment;
}

void raymarch_pixel(ivec2 pixel)
{
    if (any(greaterThanEqual(pixel, image_size)))
        return;
    uint rng = rng_seed(uint(pixel.y * image_size.x + pixel.x), frame_index, seed);
    vec2 sub = vec2(rng_next(rng), rng_next(rng));
    vec3 value = raymarch_radiance(camera_eye, camera_ray_direction(vec2(pixel) + sub), rng_next(rng));
    vec4 mean_and_count = frame_index == 0u ? vec4(0.0) : imageLoad(accumulation, pixel);
    mean_and_count.a += 1.0;
    mean_and_count.rgb += (value - mean_and_count.rgb) / mean_and_count.a;
    imageStore(accumulation, pixel, mean_and_count);
}
