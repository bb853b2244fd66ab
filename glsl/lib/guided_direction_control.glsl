// `guided`'s control variate on a scattering event's direction (lib/integrator.glsl, under
// GUIDED_RESIDUAL with GUIDED_DIRECTION_CONTROL 1). NumPy twin:
// app.twins.guided_direction_control.py direction_control.
//
// At an event at x reached along w_in, the path's estimate of what arrives there is one direction
// w drawn with density pdf(w) and the radiance a path finds along it, times phase(w) / pdf(w)
// (pdf = phase: HG, g; a BRDF's where a surface scatters). The
// probes hold an estimate of that radiance, h(w) = sum_l window_l sum_m c_lm Y_lm(w) (their SH,
// windowed as the probe renderers window it). Its mean over the phase function is known in
// closed form (Funk-Hecke: HG's Legendre coefficients are g^l):
//     E_phase[h] = integral phase(w) h(w) dw = sum_l window_l g^l sum_m c_lm Y_lm(w_in)
// which is the probes' in-scattered radiance before its clamp (lib/probes.glsl). The control
//     E_phase[h] - h(w) phase(w) / pdf(w)
// therefore has mean 0 over w drawn from pdf whatever the coefficients, for any pdf that is
// positive wherever phase is:
//     E_pdf[h phase / pdf] = integral pdf(w) h(w) phase(w) / pdf(w) dw = E_phase[h].
// Zero, stale, ten times too bright or baked for another sun, it adds variance at worst and never
// bias. It is the path's own estimator applied to h: where the probes follow the light, the
// path's radiance minus h(w), times the same weight, varies far less with w than the radiance.
// The probes' sun lobe (PROBE_SUN_LOBE) is left out of h: the SH alone make an exact control.
// coeffs: the probes' SH at x (probe_fetch); phase_over_pdf: the weight of the direction drawn
// (1 for plain HG).
vec3 guided_direction_control(vec3 coeffs[SH_COUNT], vec3 w_in, vec3 w, float phase_over_pdf)
{
    return sh_evaluate_convolved(coeffs, w_in, probe_band_factors)
           - sh_evaluate_convolved(coeffs, w, probe_window_factors) * phase_over_pdf;
}
