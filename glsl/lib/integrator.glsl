// Volumetric path tracing as a resumable state machine.
//
// A path estimates the radiance arriving at its origin from the direction -direction (light that
// travels towards the origin along -direction): full multiple scattering, at most max_bounces
// scattering events, next-event estimation towards the sun with ratio tracking, the environment for
// paths that leave the box, throughput-based Russian roulette. The probe bake runs the same paths
// from each probe (a walk continues from each scattering point). Directly seen sunlight (a delta
// light) never enters; only scattered sun and the environment do.
//
// Why resumable: a dispatch may only run a bounded number of loop iterations (Mesa's llvmpipe ends
// any invocation's loops after 65535 iterations in all; desktop drivers reset the GPU after a few
// seconds). A path therefore runs until its dispatch's loop budget is low, then its state is saved
// at a scattering event and the next dispatch continues it. Where the budget is unbounded (the
// lent NVIDIA GPU) a path simply runs to its end. A flight or a shadow ray cut short is continued
// from where tracking stopped (free flight and ratio tracking's null collisions are memoryless).
//
// ENVIRONMENT_MAP (defined or not): the environment is a map (lib/environment_map.glsl). Each
// scattering event then also samples the map (a ratio-tracked shadow ray towards a direction drawn
// from the map's distribution, after the sun's), and paths that leave the box after a scattering
// event add the map's radiance; both are weighted by the power heuristic between the map's pdf and
// the phase function's, so a small bright region is found by the map's samples and a broad one by
// the phase function's. Without it the code below is the constant environment's, unchanged.
// ENVIRONMENT_MAP_SAMPLING 0 turns the map's samples off (phase sampling alone, escapes weighted
// 1): the same estimate with more noise, kept for measuring what importance sampling gains.
//
// HYBRID_SCATTERING (the scene's surface.gradient_factor k > 0; lib/hybrid_scattering.glsl): each
// real scattering event is a surface's with probability 1 - exp(-k |grad A|) (the path's status is
// then PATH_ACTIVE_SURFACE until its next direction is drawn), and the event's kernel is the
// surface BRDF times the cosine instead of the phase function, in the sun's estimate, the map's
// sample and its MIS, the next direction (drawn from the BRDF, weighted K / pdf; never guided) and,
// at a probe renderer's gather event, the probes' radiance (diffuse irradiance from the SH and a
// specular term). Without it the code below is as it was, unchanged.
// the sun's shadow ray (ratio or residual ratio tracking)
#include "lib/sun_shadow.glsl"
#if defined(HYBRID_SCATTERING)
#include "lib/hybrid_scattering.glsl"
#endif
//
// AREA_LIGHTS (the scene has area lights on; lib/area_lights.glsl): each scattering event also
// samples a point on a light (a shadow ray to the box's boundary after the sun's and the map's:
// the lights lie outside the box), weighted by the power heuristic against the event's own
// sampling's pdf (phase, BRDF or guided mixture); a path that leaves the box and meets a light adds
// its radiance weighted the other way (and not the environment behind it); a camera ray that meets
// a light before the box sees the light. The probe renderers take no light samples before their
// gather (a light a path meets counts in full), as with the map. Without it the code is as it was.
#if defined(AREA_LIGHTS)
#include "lib/area_lights.glsl"
#endif
// probes-only (PROBE_LIGHTING 2) traces no shadow rays: at its gather event the lights' direct
// light comes from their optical-depth grid (lib/area_light_grid.glsl), as the raymarcher's.
#if defined(AREA_LIGHTS) && defined(PROBE_LIGHTING)
#if PROBE_LIGHTING == 2
#include "lib/area_light_grid.glsl"
#endif
#endif

uniform int max_bounces;
uniform float anisotropy;     // Henyey-Greenstein g
uniform int max_path_steps;   // hang guard: tracking steps one path may take in all
#if defined(WALK_SUN_GRID)
uniform float walk_sun_correction;   // least rate at which a shadow ray corrects the grid's sun
#endif
#if defined(WALK_SUN_GRID) && defined(WALK_SUN_CORRECTION)
// The walk's reservoir chose the event at x (grid transmittance `grid`, weight c / w) for the sun's
// correction, replacing any earlier choice: defined by the walk shader (glsl/probe_walks.comp).
void walk_correction_choose(vec3 x, float grid, vec3 weight_per_w);
#endif
#if defined(PROBE_LIGHTING)
// The scattering event at which a probe renderer reads the probes and ends the path (>= 1). 1 is
// the paper's renderer: the probes stand in for all light arriving at the first event but the
// sun. With k > 1 (PROBE_LIGHTING 1, `probes`: a final gather), events 1 .. k-1 are traced as the
// path tracer traces them (the sun by a shadow ray, the next direction from the phase function,
// escapes see the environment) and the probes stand in only for what arrives at event k, light
// that has scattered k times or more on its way to the eye: their error reaches the image weighted
// by the smaller share of those orders, at the cost of k - 1 more flights and shadow rays.
// probes-only takes 1 (it traces no shadow rays, which the events before k need).
uniform int probe_gather_event;
#endif

#if defined(ENVIRONMENT_MAP) && !defined(ENVIRONMENT_MAP_SAMPLING)
#define ENVIRONMENT_MAP_SAMPLING 1
#endif

#if defined(ENVIRONMENT_MAP)
// Loop iterations one map sample may take (two binary searches over at most 65536 rows/columns),
// charged to the path's step budget so the dispatch's loop budget stays honest.
const int ENVIRONMENT_SAMPLE_STEPS = 32;

// The power heuristic's weight of a strategy with pdf a against one with pdf b.
float mis_power(float a, float b)
{
    float a2 = a * a, b2 = b * b;
    return a2 + b2 > 0.0 ? a2 / (a2 + b2) : 0.0;
}
#endif

#if defined(AREA_LIGHTS) && !defined(ENVIRONMENT_MAP)
// The power heuristic's weight of a strategy with pdf a against one with pdf b.
float mis_power(float a, float b)
{
    float a2 = a * a, b2 = b * b;
    return a2 + b2 > 0.0 ? a2 / (a2 + b2) : 0.0;
}
#endif

#ifndef RR_START_BOUNCE
#define RR_START_BOUNCE 3
#endif

// Independent shadow rays towards the sun per scattering event, averaged (1: the renderers'; more:
// an experiment's near-noiseless shadow ray, measuring how much of a path's variance the shadow
// ray's own noise holds: lab/experiments/experiment_shadow_variance.py,
// LabOptions.sun_shadow_rays). The mean is the same for any count.
#ifndef SUN_SHADOW_RAYS
#define SUN_SHADOW_RAYS 1
#endif

const int PATH_IDLE = 0;
const int PATH_ACTIVE = 1;
#if defined(HYBRID_SCATTERING)
const int PATH_ACTIVE_SURFACE = 2;   // active, at an event the surface BRDF scatters (p.x, p.w)
#endif

const int PATH_DONE = 0;
const int PATH_SUSPENDED = 1;
const int PATH_TRUNCATED = 2;

// std430-friendly: five 16-byte rows (80 bytes; app/rendering/probes/bake.py PATH_STATE_BYTES); seven
// (112 bytes) with ENVIRONMENT_MAP.
struct PathState {
    vec3 x;             // current vertex (origin, then each scattering point)
    int bounce;         // scattering events so far
    vec3 w;             // direction the path travels from x
    uint rng;
    vec3 throughput;
    int steps_used;     // tracking steps so far (against max_path_steps)
    vec3 radiance;      // estimate so far
    int status;         // PATH_IDLE or PATH_ACTIVE
    float shadow_t;     // a shadow ray in progress at x: distance tracked so far (< 0: not begun)
    float shadow_transmittance;  // and its ratio-tracking estimate so far
    int shadow_pending; // the sun's shadow rays of the event at x still to finish (0: none)
#if defined(WALK_SUN_GRID)
    float correction_rate_sum;   // the walk's events' correction rates summed (see path_flight)
    // The reservoir's weight sum W. Its candidate (where, c / w, the grid's transmittance there)
    // goes straight to the walk's buffer entries (walk_correction_choose, glsl/probe_walks.comp):
    // held here, in registers through every tracking step, it made the walks 18% slower on an
    // H200 (bench/h200-bake-speed). The pads keep the resumable state's layout.
    vec3 correction_pad0;
    float correction_w_sum;
    vec4 correction_pad1;
#else
    int pad;
#endif
#if defined(ENVIRONMENT_MAP)
    vec3 env_w;         // the map sample's direction at x
    float phase_pdf;    // pdf of the phase sampling that chose w (0: w was not phase-sampled)
    vec3 env_weight;    // its radiance x phase x MIS weight / pdf, to be times its transmittance
    int env_pending;    // 1 while the map sample's shadow ray at x is unfinished
#endif
#if defined(AREA_LIGHTS)   // 32 bytes more
    vec3 light_w;       // the area light sample's direction at x
    int light_pending;  // its shadow ray: 2 not begun, 1 under way, 0 none
    vec3 light_weight;  // its radiance x kernel x MIS weight / pdf, to be times its transmittance
    float light_direction_pdf;  // pdf of the sampling that chose w (0: a light met counts in full)
#endif
};

void path_begin(inout PathState p, vec3 origin, vec3 direction, uint rng)
{
    p.x = origin;
    p.bounce = 0;
    p.w = direction;
    p.rng = rng;
    p.throughput = vec3(1.0);
    p.steps_used = 0;
    p.radiance = vec3(0.0);
    p.status = PATH_ACTIVE;
    p.shadow_t = -1.0;
    p.shadow_transmittance = 1.0;
    p.shadow_pending = 0;
#if defined(WALK_SUN_GRID)
    p.correction_rate_sum = 0.0;
    p.correction_pad0 = vec3(0.0);
    p.correction_w_sum = 0.0;
    p.correction_pad1 = vec4(0.0);
#else
    p.pad = 0;
#endif
#if defined(ENVIRONMENT_MAP)
    p.env_w = vec3(0.0);
    p.phase_pdf = 0.0;
    p.env_weight = vec3(0.0);
    p.env_pending = 0;
#endif
#if defined(AREA_LIGHTS)
    p.light_w = vec3(0.0);
    p.light_pending = 0;
    p.light_weight = vec3(0.0);
    p.light_direction_pdf = 0.0;
#endif
}

#if defined(HYBRID_SCATTERING)
// The opacity gradient at the path's event, kept from its flight for the rest of the step (the
// event's choice, the normal for its lights and its next direction: 6 fetches an event, not 18);
// a step that resumes a shadow ray cut in an earlier dispatch computes it again.
vec3 path_event_gradient = vec3(0.0);
bool path_event_gradient_known = false;

// The surface normal at the path's event, facing back along its arriving direction p.w.
vec3 path_surface_normal(PathState p)
{
    if (!path_event_gradient_known) {
        path_event_gradient = opacity_gradient(p.x);
        path_event_gradient_known = true;
    }
    return surface_normal(path_event_gradient, -p.w);
}

#endif

// The event's kernel towards the light direction l (unit, towards the light): the phase function
// (the same in every channel), or at a surface event the BRDF times the cosine
// (lib/hybrid_scattering.glsl). Every light's estimate at an event (the sun's shadow ray or light
// grid, the probes' stored sun, an area light's sample) weighs by it.
vec3 path_event_kernel(PathState p, vec3 l)
{
#if defined(HYBRID_SCATTERING)
    if (p.status == PATH_ACTIVE_SURFACE)
        return surface_kernel(path_surface_normal(p), -p.w, l, surface_roughness,
                              surface_specular);
#endif
    return vec3(phase_hg(dot(l, p.w), anisotropy));
}

#if defined(ENVIRONMENT_MAP)
// The map's radiance for a path that leaves the box along p.w: weighted against the map's own
// samples where p.w was phase-sampled at a scattering event.
vec3 path_escape_radiance(PathState p)
{
    vec3 le = environment_radiance(p.w);
    if (ENVIRONMENT_MAP_SAMPLING != 0 && p.phase_pdf > 0.0)
        le *= mis_power(p.phase_pdf, environment_pdf(p.w));
    return le;
}
#endif

const int STEP_CONTINUE = 0;
const int STEP_DONE = 1;
const int STEP_FLIGHT_CUT = 2;     // steps ran out mid-flight; p.x moved to where tracking stopped
const int STEP_SHADOW_CUT = 3;     // steps ran out in a shadow ray; its progress is kept in p

// The radiance a path that leaves the box along p.w adds. GUIDED_RESIDUAL (`guided`'s level 1): a
// camera ray that leaves without scattering adds nothing, since level 0's estimate of the same
// ray (lib/guided_level0.glsl) holds exactly what it would (the environment through the
// ray's transmittance).
vec3 path_escape(PathState p)
{
#if defined(AREA_LIGHTS)
    // A light met on the way out hides the environment behind it.
    float t_light;
    int light = area_light_first_hit(p.x, p.w, t_light);
    if (light >= 0) {
#if defined(PROBE_WALKS)
        // A walk that meets a light before it scatters adds nothing, as it adds no direct sun:
        // the probes hold the light that scattered on its way, and their readers add the direct
        // part themselves (`probes`: a light sample at its gather event).
        if (p.bounce == 0)
            return vec3(0.0);
#endif
        vec3 le = area_light_emitted(light, p.w);
#if defined(GUIDED_RESIDUAL)
        if (p.bounce == 0) {   // level 0 holds the environment through this ray: taken back out
#if defined(ENVIRONMENT_MAP)
            return p.throughput * (le - environment_radiance(p.w));
#else
            return p.throughput * (le - environment);
#endif
        }
#endif
        float weight = p.light_direction_pdf > 0.0
            ? mis_power(p.light_direction_pdf, area_light_pdf(light, p.x, p.w, t_light)) : 1.0;
        return p.throughput * le * weight;
    }
#endif
#if defined(GUIDED_RESIDUAL)
    if (p.bounce == 0)
        return vec3(0.0);
#endif
#if defined(ENVIRONMENT_MAP)
    return p.throughput * path_escape_radiance(p);
#else
    return p.throughput * environment;
#endif
}

// The flight to the next scattering event and what happens there before the shadow ray: returns
// STEP_DONE, STEP_FLIGHT_CUT, or STEP_CONTINUE with p at the event (p.shadow_pending set when the
// sun needs a shadow ray from there).
int path_flight(inout PathState p, inout int steps_left)
{
    float t0, t1;
    if (!box_intersect(p.x, p.w, t0, t1)) {
        p.radiance += path_escape(p);
        return STEP_DONE;
    }
#if defined(AREA_LIGHTS)
    if (p.bounce == 0 && t0 > 0.0) {   // a camera ray meets a light before it reaches the box
        float t_light;
        int light = area_light_first_hit(p.x, p.w, t_light);
        if (light >= 0 && t_light < t0) {
            p.radiance += p.throughput * area_light_emitted(light, p.w);
            return STEP_DONE;
        }
    }
#endif
    float t;
    int event = delta_track(p.x, p.w, t0, t1, p.rng, steps_left, t);
    if (event == TRACK_ESCAPED) {
        p.radiance += path_escape(p);
        return STEP_DONE;
    }
    if (event == TRACK_OUT_OF_STEPS) {
        p.x += t * p.w;
        return STEP_FLIGHT_CUT;
    }
    if (p.bounce >= max_bounces)
        return STEP_DONE;  // this event would be scattering number max_bounces + 1
    p.bounce += 1;
    p.x += t * p.w;
    p.throughput *= albedo_at(p.x);
    if (all(equal(p.throughput, vec3(0.0))))
        return STEP_DONE;
#if defined(HYBRID_SCATTERING)
    // A surface's event with probability 1 - exp(-k |grad A|) (lib/hybrid_scattering.glsl).
    p.status = PATH_ACTIVE;
    path_event_gradient = opacity_gradient(p.x);
    path_event_gradient_known = true;
    if (rng_next(p.rng) < surface_probability(path_event_gradient, surface_gradient_factor))
        p.status = PATH_ACTIVE_SURFACE;
#endif
#if defined(GUIDED_RESIDUAL)
    // `guided`'s level 1: minus the single-collision estimate of level 0's F at this first event
    // (the same random numbers: the same collision), so the sample is the path's estimate minus
    // what the probes and the light grid predict for it (lib/guided_level0.glsl).
    if (p.bounce == 1)
        p.radiance -= p.throughput * guided_predicted_source(
            p.x, p.w, phase_hg(dot(sun_direction, p.w), anisotropy));
#endif
#if defined(PROBE_LIGHTING)
    // Render from probes: at the gather event (the first unless probe_gather_event says
    // otherwise), light arriving by further bounces comes from the probes (convolved with the
    // phase function); the sun from a shadow ray (probes) or from the probes' stored sun
    // transmittance (probes-only). The path ends there.
    if (p.bounce >= probe_gather_event) {
        float probe_sun_transmittance;
#if defined(HYBRID_SCATTERING)
        if (p.status == PATH_ACTIVE_SURFACE) {
            vec3 coeffs[SH_COUNT];
            probe_fetch(p.x, coeffs, probe_sun_transmittance);
            p.radiance += p.throughput * surface_probe_radiance(coeffs, path_surface_normal(p),
                                                                -p.w, surface_specular);
        } else {
#endif
        p.radiance += p.throughput * probe_inscattered(p.x, p.w, probe_sun_transmittance);
#if defined(HYBRID_SCATTERING)
        }
#endif
#if defined(AREA_LIGHTS) && PROBE_LIGHTING == 1
        // The probes hold no direct light from the area lights (PROBE_WALKS): a light sample
        // here adds it, in full (the path ends here, so no path of its own meets the light).
        {
            float light_pdf;
            vec3 light_le;
            float u0 = rng_next(p.rng), u1 = rng_next(p.rng), u2 = rng_next(p.rng);
            vec3 light_w = area_light_sample(p.x, u0, u1, u2, light_le, light_pdf);
            p.light_pending = 0;
            if (light_pdf > 0.0 && any(greaterThan(light_le, vec3(0.0)))) {
                vec3 kernel = path_event_kernel(p, light_w);
                p.light_w = light_w;
                p.light_weight = light_le * kernel / light_pdf;
                p.light_pending = 2;
            }
        }
#endif
#if PROBE_LIGHTING == 2
        p.radiance += p.throughput * sun_irradiance
                      * (probe_sun_transmittance * path_event_kernel(p, sun_direction));
#if defined(AREA_LIGHTS)
        for (int l = 0; l < area_light_count; ++l) {
            vec3 area_w;
            float area_omega;
            vec3 area_le = area_light_direct(l, p.x, area_w, area_omega);
            vec3 area_kernel = vec3(phase_hg(dot(area_w, p.w),
                                             area_light_anisotropy(anisotropy, area_omega)));
#if defined(HYBRID_SCATTERING)
            if (p.status == PATH_ACTIVE_SURFACE)
                area_kernel = path_event_kernel(p, area_w);
#endif
            p.radiance += p.throughput * area_le * area_kernel;
        }
#endif
        return STEP_DONE;
#endif
    }
#endif
#if defined(ENVIRONMENT_MAP) && !defined(PROBE_LIGHTING)
    // A direction from the map's distribution; its shadow ray runs after the sun's.
    if (ENVIRONMENT_MAP_SAMPLING != 0) {
        float env_pdf;
        vec3 env_w = environment_sample(rng_next(p.rng), rng_next(p.rng), env_pdf);
        steps_left -= ENVIRONMENT_SAMPLE_STEPS;
        p.env_pending = 0;
#if defined(HYBRID_SCATTERING)
        if (env_pdf > 0.0 && p.status == PATH_ACTIVE_SURFACE) {
            // a surface's event: the BRDF's kernel, weighted against its own sampling's pdf
            vec3 n = path_surface_normal(p);
            vec3 le = environment_radiance(env_w)
                      * surface_kernel(n, -p.w, env_w, surface_roughness, surface_specular);
            if (any(greaterThan(le, vec3(0.0)))) {
                float direction_pdf = surface_pdf(n, -p.w, env_w, surface_roughness,
                                                  surface_specular);
                p.env_w = env_w;
                p.env_weight = le * (mis_power(env_pdf, direction_pdf) / env_pdf);
                p.env_pending = 1;
                p.shadow_t = -1.0;
                p.shadow_transmittance = 1.0;
            }
        } else
#endif
        if (env_pdf > 0.0) {
            float phase = phase_hg(dot(env_w, p.w), anisotropy);
            vec3 le = environment_radiance(env_w);
            if (any(greaterThan(le, vec3(0.0)))) {
                // the pdf with which path_step would draw env_w at this event
                float direction_pdf = phase;
                p.env_w = env_w;
                p.env_weight = le * (phase * mis_power(env_pdf, direction_pdf) / env_pdf);
                p.env_pending = 1;
                p.shadow_t = -1.0;
                p.shadow_transmittance = 1.0;
            }
        }
    }
#endif
#if defined(AREA_LIGHTS) && !defined(PROBE_LIGHTING)
    // A direction towards an area light (lib/area_lights.glsl); its shadow ray runs after the
    // sun's and the map's, weighted against the pdf with which path_step would draw it.
    {
        float light_pdf;
        vec3 light_le;
        float u0 = rng_next(p.rng), u1 = rng_next(p.rng), u2 = rng_next(p.rng);
        vec3 light_w = area_light_sample(p.x, u0, u1, u2, light_le, light_pdf);
        p.light_pending = 0;
        if (light_pdf > 0.0 && any(greaterThan(light_le, vec3(0.0)))) {
            vec3 kernel;
            float direction_pdf;
#if defined(HYBRID_SCATTERING)
            if (p.status == PATH_ACTIVE_SURFACE) {
                vec3 n = path_surface_normal(p);
                kernel = surface_kernel(n, -p.w, light_w, surface_roughness, surface_specular);
                direction_pdf = surface_pdf(n, -p.w, light_w, surface_roughness,
                                            surface_specular);
            } else
#endif
            {
                float phase = phase_hg(dot(light_w, p.w), anisotropy);
                kernel = vec3(phase);
                direction_pdf = phase;
            }
            if (any(greaterThan(kernel, vec3(0.0)))) {
                p.light_w = light_w;
                p.light_weight = light_le * kernel
                                 * (mis_power(light_pdf, direction_pdf) / light_pdf);
                p.light_pending = 2;
            }
        }
    }
#endif
#if defined(WALK_SUN_GRID)
    // The sun's transmittance from the baked light grid (lib/light_grid.glsl), corrected without
    // bias by a shadow ray traced after the walk (glsl/probe_sun_correction.comp). The grid's
    // interpolation errs (on a thin backlit shell or a pinhole's beam it made probes 2.3-7.5%
    // dark: bench/h100-bias); the correction of event k is c_k (T_ray,k - T_grid,k), c_k the
    // event's sun weight. The walk keeps one event of all its events (weighted reservoir sampling,
    // weights w_k = lum(c_k) q_k) and, with probability Q = min(1, sum q_k), the pass after it adds
    // W c_k / w_k (T_ray,k - T_grid,k) / Q, W = sum w_k: its mean over the choice and the coin is
    // sum_k c_k E[T_ray,k - T_grid,k], the exact sun's, whatever the grid's error. q_k is the
    // rate at which the event would deserve a ray of its own: walk_sun_correction where the grid is
    // flat, up to 0.5 where its optical depth changes by a unit or more over the texel towards the
    // sun (where its interpolation errs). The ray is not traced in the walk: a shadow ray's code
    // in the walk shader made every walk 2-2.5x slower on an H100 whether or not it ran
    // (bench/h100-bake-split). walk_sun_correction = 0: the grid alone (biased).
    if (any(greaterThan(sun_irradiance, vec3(0.0)))) {
        float tau = light_grid_optical_depth(p.x);
        float grid = exp(-tau);
        vec3 c = p.throughput * sun_irradiance * path_event_kernel(p, sun_direction);
        p.radiance += c * grid;
#if defined(WALK_SUN_CORRECTION)   // compiled where the rate is above 0 (its code alone made the
                                   // walks 18% slower on an H200: bench/h200-bake-speed)
        if (walk_sun_correction > 0.0) {
            float change = tau - light_grid_optical_depth(p.x + light_grid_texel * sun_direction);
            float q = clamp(walk_sun_correction * (1.0 + 8.0 * change), walk_sun_correction, 0.5);
            float w = max(c.r, max(c.g, c.b)) * q;
            if (w > 0.0) {
                p.correction_w_sum += w;
                if (rng_next(p.rng) * p.correction_w_sum < w)
                    walk_correction_choose(p.x, grid, c / w);
                p.correction_rate_sum += q;
            }
        }
#endif
    }
    return STEP_CONTINUE;
#endif
    if (any(greaterThan(sun_irradiance, vec3(0.0)))) {
        p.shadow_t = -1.0;
        p.shadow_transmittance = 1.0;
        p.shadow_pending = SUN_SHADOW_RAYS;
    }
    return STEP_CONTINUE;
}

// One flight to the next scattering event, its sun estimate and the choice of the next direction.
// After STEP_SHADOW_CUT the next call resumes the shadow ray where it stopped, then goes on.
int path_step(inout PathState p, inout int steps_left)
{
#if defined(HYBRID_SCATTERING)
    path_event_gradient_known = false;   // this step's flight (if it flies) computes it
#endif
#if defined(ENVIRONMENT_MAP) && defined(AREA_LIGHTS)
    if (p.shadow_pending == 0 && p.env_pending == 0 && p.light_pending == 0) {
#elif defined(AREA_LIGHTS)
    if (p.shadow_pending == 0 && p.light_pending == 0) {
#elif defined(ENVIRONMENT_MAP)
    if (p.shadow_pending == 0 && p.env_pending == 0) {
#else
    if (p.shadow_pending == 0) {
#endif
        int flight = path_flight(p, steps_left);
        if (flight != STEP_CONTINUE)
            return flight;
    }
#if !defined(WALK_SUN_GRID)   // grid-sun walks trace no shadow ray (their correction comes after)
    // SUN_SHADOW_RAYS rays in turn, each adding its share; a cut one resumes where it stopped.
    while (p.shadow_pending > 0) {
        if (!sun_transmittance_continue(p.x, p.shadow_t, p.shadow_transmittance, p.rng,
                                        steps_left))
            return STEP_SHADOW_CUT;
        p.shadow_pending -= 1;
        p.radiance += p.throughput * sun_irradiance
                      * (p.shadow_transmittance * path_event_kernel(p, sun_direction)
                         / float(SUN_SHADOW_RAYS));
        p.shadow_t = -1.0;          // the next ray (or the map sample's) starts afresh
        p.shadow_transmittance = 1.0;
    }
#endif
#if defined(ENVIRONMENT_MAP)
    if (p.env_pending != 0) {
        if (!transmittance_to_boundary_continue(p.x, p.env_w, p.shadow_t,
                                                p.shadow_transmittance, p.rng, steps_left))
            return STEP_SHADOW_CUT;
        p.env_pending = 0;
        p.radiance += p.throughput * p.env_weight * p.shadow_transmittance;
    }
#endif
#if defined(AREA_LIGHTS)
    if (p.light_pending != 0) {
        if (p.light_pending == 2) {   // its shadow ray starts afresh
            p.shadow_t = -1.0;
            p.shadow_transmittance = 1.0;
            p.light_pending = 1;
        }
        if (!transmittance_to_boundary_continue(p.x, p.light_w, p.shadow_t,
                                                p.shadow_transmittance, p.rng, steps_left))
            return STEP_SHADOW_CUT;
        p.light_pending = 0;
        p.radiance += p.throughput * p.light_weight * p.shadow_transmittance;
    }
#endif
#if defined(PROBE_LIGHTING)
    if (p.bounce >= probe_gather_event)
        return STEP_DONE;
#endif
    vec3 w_in = p.w;
    float phase_over_pdf = 1.0;   // the direction's weight: 1 where drawn from the phase function
#if defined(HYBRID_SCATTERING)
    if (p.status == PATH_ACTIVE_SURFACE) {
        // A surface's event: the next direction from the BRDF (never guided), weighted K / pdf.
        vec3 n = path_surface_normal(p);   // (p.w is still w_in)
        p.status = PATH_ACTIVE;
        vec3 surface_weight;
        float surface_direction_pdf;
        float u0 = rng_next(p.rng), u1 = rng_next(p.rng), u2 = rng_next(p.rng);
        p.w = surface_sample(n, -w_in, surface_roughness, surface_specular, u0, u1, u2,
                             surface_weight, surface_direction_pdf);
        p.throughput *= surface_weight;
        if (all(equal(p.throughput, vec3(0.0))))
            return STEP_DONE;   // below the surface: the BRDF sends no light that way
#if defined(ENVIRONMENT_MAP) && defined(PROBE_LIGHTING)
        p.phase_pdf = 0.0;
#elif defined(ENVIRONMENT_MAP)
        p.phase_pdf = surface_direction_pdf;
#endif
#if defined(AREA_LIGHTS) && defined(PROBE_LIGHTING)
        p.light_direction_pdf = 0.0;
#elif defined(AREA_LIGHTS)
        p.light_direction_pdf = surface_direction_pdf;
#endif
        if (p.bounce >= RR_START_BOUNCE) {
            float q = max(p.throughput.r, max(p.throughput.g, p.throughput.b));
            if (q < 1.0) {
                if (rng_next(p.rng) >= q)
                    return STEP_DONE;
                p.throughput /= q;
            }
        }
        return STEP_CONTINUE;
    }
#endif
#if defined(GUIDED_RESIDUAL) && GUIDED_DIRECTION_CONTROL
    // The control reads the probes at the event; not at the last event the path may scatter at
    // (what follows it is an escape alone, which the probes' radiance does not track).
    bool guide = p.bounce < max_bounces;
    vec3 event_coeffs[SH_COUNT];
    if (guide) {
        float probe_sun;
        probe_fetch(p.x, event_coeffs, probe_sun);
    }
#endif
    p.w = sample_hg(w_in, anisotropy, rng_next(p.rng), rng_next(p.rng));
#if defined(GUIDED_RESIDUAL) && GUIDED_DIRECTION_CONTROL
    // `guided`'s control variate on the direction (lib/guided_direction_control.glsl): the probes'
    // radiance expected over the phase function minus their radiance in the direction drawn,
    // times its weight. Its mean is 0 at any probes, so the estimate stays unbiased; where the
    // probes follow the light, it takes out the noise of which direction was drawn.
    if (guide)
        p.radiance += p.throughput * guided_direction_control(event_coeffs, w_in, p.w,
                                                              phase_over_pdf);
#endif
    p.throughput *= phase_over_pdf;
#if defined(ENVIRONMENT_MAP) && defined(PROBE_LIGHTING)
    // The probe renderers take no map samples at the events before the gather: an escape counts
    // in full (phase_pdf 0), as it would with ENVIRONMENT_MAP_SAMPLING 0.
    p.phase_pdf = 0.0;
#elif defined(ENVIRONMENT_MAP)
    p.phase_pdf = phase_hg(dot(w_in, p.w), anisotropy) / phase_over_pdf;
#endif
#if defined(AREA_LIGHTS) && defined(PROBE_LIGHTING)
    p.light_direction_pdf = 0.0;   // the probe renderers take no light samples before the gather
#elif defined(AREA_LIGHTS)
    p.light_direction_pdf = phase_hg(dot(w_in, p.w), anisotropy) / phase_over_pdf;
#endif
    if (p.bounce >= RR_START_BOUNCE) {
        float q = max(p.throughput.r, max(p.throughput.g, p.throughput.b));
        if (q < 1.0) {
            if (rng_next(p.rng) >= q)
                return STEP_DONE;
            p.throughput /= q;
        }
    }
    return STEP_CONTINUE;
}

// Runs the path until it ends (PATH_DONE), its budgets run out (PATH_TRUNCATED), or the dispatch's
// loop budget falls to the reserve one more flight may need (PATH_SUSPENDED, state kept in p).
int path_continue(inout PathState p, inout int loop_budget, int reserve)
{
    for (;;) {
        if (loop_budget <= reserve)
            return PATH_SUSPENDED;
        loop_budget -= 1;
        int path_left = max_path_steps - p.steps_used;
        if (path_left <= 0)
            return PATH_TRUNCATED;
        bool dispatch_bound = loop_budget < path_left;
        int steps_left = min(path_left, loop_budget);
        int before = steps_left;
        int result = path_step(p, steps_left);
        p.steps_used += before - steps_left;
        loop_budget -= before - steps_left;
        if (result == STEP_DONE)
            return PATH_DONE;
        if (result == STEP_FLIGHT_CUT || result == STEP_SHADOW_CUT)
            return dispatch_bound ? PATH_SUSPENDED : PATH_TRUNCATED;
    }
    return PATH_TRUNCATED;  // reached only if a driver cut the loop short
}

// Whether a finished path's estimate may be averaged; truncated and non-finite estimates are
// counted in tracking_stats instead, never averaged.
bool path_estimate_valid(PathState p, int result)
{
    if (result == PATH_TRUNCATED) {
        atomicAdd(tracking_stats.truncated_paths, 1u);
        return false;
    }
    if (any(isnan(p.radiance)) || any(isinf(p.radiance))) {
        atomicAdd(tracking_stats.nonfinite_samples, 1u);
        return false;
    }
    return true;
}

#include "lib/running_mean.glsl"

// Adds a finished path to a running mean (rgb mean, a count) if its estimate is valid.
void path_finish(inout vec4 mean_and_count, PathState p, int result)
{
    if (path_estimate_valid(p, result))
        mean_and_count = running_mean_add(mean_and_count, p.radiance);
}
