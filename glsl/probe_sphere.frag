// A probe sphere's colour: the probe's SH radiance evaluated at the sphere's normal, i.e. the
// radiance arriving at the probe from that direction (with PROBE_SUN_LOBE plus its lobe about the
// sun's direction, lib/sun_lobe.glsl), clamped to non-negative values, tone mapped.
#define PROBE_SAMPLING
#include "probe_common.glsl"

uniform float exposure;
flat in vec3 probe_centre;
in vec3 normal;
out vec4 frag_colour;

#include "lib/tonemap.glsl"

void main()
{
    vec3 coeffs[SH_COUNT];
    float sun_transmittance;
    probe_fetch(probe_centre, coeffs, sun_transmittance);  // at a texel centre: the probe itself
    vec3 n = normalize(normal);
    vec3 radiance = sh_evaluate(coeffs, n);
#if PROBE_SUN_LOBE
    radiance += probe_fetched_lobe * sun_lobe_residual(dot(n, sun_direction), sun_lobe_g,
                                                       PROBE_SH_ORDER);
#endif
    radiance = sh_clamp_nonnegative(radiance);
    frag_colour = vec4(srgb_encode(radiance * exposure), 1.0);
}
