// What `guided`'s two levels predict is scattered at x towards -d, per unit sigma_s: the probes'
// inscattered radiance (lib/probes.glsl) plus the sun through the light grid's transmittance
// (lib/light_grid.glsl). Level 0 integrates it along camera rays (lib/guided_level0.glsl); level 1
// subtracts it at a path's first event (lib/integrator.glsl GUIDED_RESIDUAL).
#include "lib/light_grid.glsl"

// The same from coefficients probe_fetch has just fetched at x.
vec3 guided_predicted_source_from(vec3 coeffs[SH_COUNT], vec3 x, vec3 d, float sun_phase)
{
    return probe_inscattered_from(coeffs, d)
           + sun_irradiance * (light_grid_transmittance(x) * sun_phase);
}

vec3 guided_predicted_source(vec3 x, vec3 d, float sun_phase)
{
    vec3 coeffs[SH_COUNT];
    float probe_sun;
    probe_fetch(x, coeffs, probe_sun);
    return guided_predicted_source_from(coeffs, x, d, sun_phase);
}
