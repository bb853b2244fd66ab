// The raymarcher (the design card's): deterministic front-to-back marching with a jittered start.
// Each step of length dt at x adds transmittance * (1 - exp(-sigma_t dt)) * albedo(x) *
// [sun * T_sun(x) * phase + probe radiance convolved with the phase function]; T_sun comes from the
// baked light-transmittance texture (light_transmittance.comp). The step's opacity is integrated
// exactly for piecewise-constant sigma_t, so large steps through dense media stay bounded.
// Shared by raymarch.comp and raymarch.frag; each calls raymarch_pixel for its pixel. With
// ENVIRONMENT_MAP the environment behind the volume is the map's radiance along the ray.
// Empty space is skipped exactly: a step whose sample is empty looks up its macrocell in the
// majorant grid (lib/cell_walk.glsl), and where that bounds sigma_t by 0 every sample before the
// cell's exit is empty too, so the march goes on from the last sample before the exit. The same
// samples contribute as without skipping (test_raymarch_skipping_empty_space_changes_nothing).
//
// HYBRID_SCATTERING (the scene's surface.gradient_factor k > 0; lib/hybrid_scattering.glsl): a
// sample is a surface's with probability P = 1 - exp(-k |grad A|), and the march adds the mean of
// both: (1 - P) times the phase function's light and P times the surface's, which reflects the
// probes' light by surface_probe_radiance (the diffuse irradiance from the SH in closed form and a
// specular term from the mirror direction) and the sun by the BRDF times the cosine; below
// transmittance 2e-2 a Russian roulette (hybrid_march_roulette) ends the ray or carries it on at
// 2e-2, unbiased, where without surfaces the march goes on to 1e-6 (HYBRID_MARCH_NO_ROULETTE, a
// test build, keeps that stop: tests/test_hybrid_scattering.py). The
// gradient is read from the baked opacity-gradient grid in one fetch where there is one
// (lib/opacity_gradient_grid.glsl: OPACITY_GRADIENT_GRID; exact at the voxel centres, trilinear
// between), else computed exactly. Without HYBRID_SCATTERING the code is as it was.
#if defined(HYBRID_SCATTERING)
#include "lib/hybrid_scattering.glsl"
#include "lib/opacity_gradient_grid.glsl"
// The roulette's random numbers (hybrid_march_roulette), continuing the stream that drew the
// pixel's ray and the jitter (raymarch_frame).
uint hybrid_march_rng;
#endif
// AREA_LIGHTS (lib/area_lights.glsl): a light the camera ray meets is seen, in front of the
// volume or behind it (in place of the environment); the light they shed after scattering comes
// from the probes (the walks meet and sample the lights), and their direct single scattering from
// their optical-depth grid (lib/area_light_grid.glsl): at each segment, per light, its radiance
// times its exact solid angle and the phase function (its anisotropy narrowed to the light's
// cone: area_light_anisotropy; or the surface's kernel, mixed as the sun's) towards its centre,
// times the segment's weight of the light's optical depth at the segment's two ends, as the
// sun's (segment_sun_weight; the end carried to the next segment).
#if defined(AREA_LIGHTS)
#include "lib/area_lights.glsl"
#include "lib/area_light_grid.glsl"
#endif
uniform float raymarch_step;            // world units
uniform uint frame_index;               // keys the jitter; frames accumulate into a running mean
uniform uint seed;

// After an empty sample i at ray distance t: where the majorant grid bounds sigma_t by 0 in the
// sample's macrocell, every sample up to that cell's exit is empty, and the march may go on from
// the last of them (the index returned; the loop's ++i moves past it); i itself otherwise.
// Rounding can only make the march look at one more sample inside the empty cell (floor), never
// skip one beyond it.
int empty_space_last_index(vec3 origin, vec3 d, float t, int i, float t0, float dt, float jitter)
{
#if !defined(GLOBAL_MAJORANT)
    CellWalk w;
    if (use_majorant_grid == 0 || !cell_walk_begin(origin, d, t, w) || cell_majorant(w) > 0.0)
        return i;
    return max(i, int(floor((cell_walk_exit(w) - t0) / dt - jitter)) - 1);
#else
    return i;
#endif
}

layout(rgba32f, binding = 0) uniform image2D accumulation;  // rgb: running mean, a: frames

vec3 raymarch_radiance(vec3 origin, vec3 d, float jitter)
{
#if defined(ENVIRONMENT_MAP)
    vec3 environment = environment_radiance(d);   // the background this ray sees
#endif
#if defined(AREA_LIGHTS)
    float t_light;
    int light = area_light_first_hit(origin, d, t_light);
    vec3 background = light >= 0 ? area_light_emitted(light, d) : environment;
    float t0, t1;
    if (!box_intersect(origin, d, t0, t1) || (light >= 0 && t_light < t0))
        return background;
#else
    float t0, t1;
    if (!box_intersect(origin, d, t0, t1))
        return environment;
#endif
    int n = clamp(int(ceil((t1 - t0) / raymarch_step)), 1, 8192);
    float dt = (t1 - t0) / float(n);
    float transmittance = 1.0;
    vec3 radiance = vec3(0.0);
    float scatter_allowed = max_bounces > 0 ? 1.0 : 0.0;
    float sun_phase = phase_hg(dot(sun_direction, d), anisotropy);
    // Segment i is [t0 + i dt, t0 + (i + 1) dt], sampled at its jittered point for sigma_t, the
    // colour and the probes; the sun's optical depth at its two ends, the end carried over to the
    // next segment (-1: not fetched, after a jump over empty space).
    float tau_start = -1.0;
#if defined(AREA_LIGHTS)
    float area_tau_start[AREA_LIGHTS_MAX];   // each light's, as tau_start
    for (int l = 0; l < AREA_LIGHTS_MAX; ++l)
        area_tau_start[l] = -1.0;
#endif
    for (int i = 0; i < n && transmittance > 1e-6; ++i) {
        float t = t0 + (float(i) + jitter) * dt;
        vec3 x = origin + t * d;
        vec4 tf = classified_at(x);
        float sigma_t = density_scale * tf.a;
        if (sigma_t <= 0.0) {
            int last = empty_space_last_index(origin, d, t, i, t0, dt, jitter);
            CHECK_TRUE(last >= i, CHECK_SITE_MARCH_LOOP);   // never back
            i = last;
            tau_start = -1.0;
#if defined(AREA_LIGHTS)
            for (int l = 0; l < AREA_LIGHTS_MAX; ++l)
                area_tau_start[l] = -1.0;
#endif
            continue;
        }
        float opacity = 1.0 - exp(-sigma_t * dt);
#if defined(HYBRID_SCATTERING)
        // the coefficients as stored: the probes' radiance scale goes on the mixed light below,
        // not on the 27 coefficients (every term is linear in them, and the clamps at 0 keep
        // their sign: the same light to rounding; bench/h200-hybrid-cost)
        vec3 coeffs[SH_COUNT];
        float probe_sun;
        probe_fetch_scaled(x, coeffs, probe_sun, 1.0);
        vec3 inscattered = probe_inscattered_from(coeffs, d);
        vec3 sun_kernel = vec3(sun_phase);
        vec3 gradient = raymarch_opacity_gradient(x);
        float surface_share = surface_probability(gradient, surface_gradient_factor);
#if defined(AREA_LIGHTS)
        vec3 area_surface_normal = vec3(0.0);
#endif
        if (surface_share > 0.0) {
            vec3 n = surface_normal(gradient, -d);
#if defined(AREA_LIGHTS)
            area_surface_normal = n;
#endif
            inscattered = mix(inscattered, surface_probe_radiance(coeffs, n, -d, surface_specular),
                              surface_share);
            sun_kernel = mix(sun_kernel, surface_kernel(n, -d, sun_direction, surface_roughness,
                                                        surface_specular), vec3(surface_share));
        }
        inscattered *= probe_radiance_scale;
#else
        float probe_sun;
        vec3 inscattered = probe_inscattered(x, d, probe_sun);
#endif
        if (tau_start < 0.0)
            tau_start = light_grid_optical_depth(origin + (t0 + float(i) * dt) * d);
        float tau_end = light_grid_optical_depth(origin + (t0 + float(i + 1) * dt) * d);
        float sun_weight = segment_sun_weight(sigma_t, dt, tau_start, tau_end);
        tau_start = tau_end;
#if defined(AREA_LIGHTS)
        vec3 area_direct = vec3(0.0);   // the lights' radiance x solid angle x kernel x weight
        for (int l = 0; l < AREA_LIGHTS_MAX; ++l) {
            if (l >= area_light_count)
                break;
            if (area_tau_start[l] < 0.0)
                area_tau_start[l] = area_light_optical_depth(l, origin + (t0 + float(i) * dt) * d);
            float area_tau_end = area_light_optical_depth(l, origin + (t0 + float(i + 1) * dt) * d);
            float area_weight = segment_sun_weight(sigma_t, dt, area_tau_start[l], area_tau_end);
            area_tau_start[l] = area_tau_end;
            vec3 area_w = normalize(area_light_position[l] - x);
            float area_omega = area_light_solid_angle(l, x);
            vec3 area_kernel = vec3(phase_hg(dot(area_w, d),
                                             area_light_anisotropy(anisotropy, area_omega)));
#if defined(HYBRID_SCATTERING)
            if (surface_share > 0.0)
                area_kernel = mix(area_kernel, surface_kernel(area_surface_normal, -d, area_w,
                                                              surface_roughness, surface_specular),
                                  vec3(surface_share));
#endif
            area_direct += area_light_radiance[l]
                           * (area_omega * area_weight) * area_kernel;
        }
#endif
#if defined(HYBRID_SCATTERING)
        vec3 source = albedo * tf.rgb * (opacity * inscattered
                                         + sun_irradiance * (sun_weight * sun_kernel));
#else
        vec3 source = albedo * tf.rgb * (opacity * inscattered
                                         + sun_irradiance * (sun_weight * sun_phase));
#endif
#if defined(AREA_LIGHTS)
        source += albedo * tf.rgb * area_direct;
#endif
        radiance += transmittance * scatter_allowed * source;
        transmittance *= 1.0 - opacity;
#if defined(HYBRID_SCATTERING) && !defined(HYBRID_MARCH_NO_ROULETTE)
        if (transmittance < HYBRID_MARCH_ROULETTE_TRANSMITTANCE)
            transmittance = hybrid_march_roulette(transmittance, rng_next(hybrid_march_rng));
#endif
    }
#if defined(AREA_LIGHTS)
    return radiance + transmittance * background;
#else
    return radiance + transmittance * environment;
#endif
}

#if defined(GUIDED_LEVEL0)
#include "lib/guided_level0.glsl"
#endif

// One jittered frame's radiance through a pixel; the frame number keys the jitter. GUIDED_LEVEL0:
// `guided`'s unbiased level 0 instead of the raymarcher's quadrature (lib/guided_level0.glsl).
vec3 raymarch_frame(ivec2 pixel, uint frame)
{
    uint rng = rng_seed(uint(pixel.y * image_size.x + pixel.x), frame, seed);
    vec2 sub = vec2(rng_next(rng), rng_next(rng));
#if defined(GUIDED_LEVEL0)
    return guided_level0_radiance(camera_eye, camera_ray_direction(vec2(pixel) + sub), rng);
#endif
    float jitter = rng_next(rng);
#if defined(HYBRID_SCATTERING)
    hybrid_march_rng = rng;   // after the jitter's draw: the ray and the jitter as without surfaces
#endif
    return raymarch_radiance(camera_eye, camera_ray_direction(vec2(pixel) + sub), jitter);
}

// Adds frame frame_index to the pixel's running mean in the accumulation image.
void raymarch_pixel(ivec2 pixel)
{
    if (any(greaterThanEqual(pixel, image_size)))
        return;
    vec3 value = raymarch_frame(pixel, frame_index);
    CHECK_TEXEL(pixel, imageSize(accumulation), CHECK_SITE_IMAGE_TEXEL);
    vec4 mean_and_count = frame_index == 0u ? vec4(0.0) : imageLoad(accumulation, pixel);
    imageStore(accumulation, pixel, running_mean_add(mean_and_count, value));
}
