// `guided`'s control variate on a scattering event's direction (lib/integrator.glsl, under
// GUIDED_RESIDUAL with GUIDED_DIRECTION_CONTROL 1). NumPy twin:
// app.twins.guided_direction_control.py direction_control.
//
// At an event at x reached along w_in, the path's estimate of what arrives there is one direction
// w drawn from the phase function (Henyey-Greenstein, g) and the radiance a path finds along it.
// The probes hold an estimate of that radiance, h(w) = sum_l window_l sum_m c_lm Y_lm(w) (their
// SH, windowed as the probe renderers window it). Its mean over the phase function is known in
// closed form (Funk-Hecke: HG's Legendre coefficients are g^l):
//     E_w[h(w)] = sum_l window_l g^l sum_m c_lm Y_lm(w_in)
// which is the probes' in-scattered radiance before its clamp (lib/probes.glsl). The control
// E_w[h] - h(w) therefore has mean 0 whatever the coefficients: zero, stale, ten times too bright
// or baked for another sun, it adds variance at worst and never bias. Where the probes follow the
// light, the path's radiance minus h(w) varies far less with w than the radiance itself.
// The probes' sun lobe (PROBE_SUN_LOBE) is left out of h: the SH alone make an exact control.
uniform float probe_window_factors[SH_BANDS];   // window_l (band_factors with g = 1)

vec3 guided_direction_control(vec3 x, vec3 w_in, vec3 w)
{
    vec3 coeffs[SH_COUNT];
    float sun_transmittance;
    probe_fetch(x, coeffs, sun_transmittance);
    return sh_evaluate_convolved(coeffs, w_in, probe_band_factors)
           - sh_evaluate_convolved(coeffs, w, probe_window_factors);
}
