// What `guided`'s two levels predict is scattered at x towards -d, per unit sigma_s: the probes'
// inscattered radiance (lib/probes.glsl) plus the sun through the light grid's transmittance
// (lib/light_grid.glsl). Level 0 integrates it along camera rays (lib/guided_level0.glsl); level 1
// subtracts it at a path's first event (lib/integrator.glsl GUIDED_RESIDUAL).
#include "lib/light_grid.glsl"

vec3 guided_predicted_source(vec3 x, vec3 d, float sun_phase)
{
    float probe_sun;
    return probe_inscattered(x, d, probe_sun)
           + sun_irradiance * (light_grid_transmittance(x) * sun_phase);
}
