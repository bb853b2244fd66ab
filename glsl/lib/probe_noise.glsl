// The adaptive bake: walks per probe set by the noise of its neighbours, without bias.
//
// Each walk's radiance v (mean over rgb) is one sample; a probe's walks have variance
// var = E[v^2] - E[v]^2, estimated from its running means (ProbeAccum: E[v] from L00, E[v^2] from
// square_mean). The asked-for N walks give a probe of average variance the standard error^2
// mean_var / N; a probe of variance var reaches that target with n = N var / (factor^2 mean_var)
// walks, where factor (RenderSettings.walk_adaptive) scales the target.
//
// Why not from the probe's own walks: a count decided from the same walks that the estimate
// averages is a stopping rule on those walks, and the mean of a sample whose size depends on its
// values is biased. Where a walk's radiance is heavy-tailed (rare walks that reach a bright,
// backlit, thin rim), a probe that has not yet drawn a bright walk looks quiet, stops early and
// stays dark: measured on a backlit shell of albedo 0.99 (tests/test_bake.py), 3.5% dark at
// z = -5.5 over 40 seeds with the rule that used each probe's own running variance.
//
// The rule here: after the first pass (probe_noise.comp), each probe's count is decided once
// (probe_walk_budget.comp) from its up to 26 neighbours' first-pass variances (their mean) and
// from the mean variance over every probe but itself, never from its own walks. A probe's walks
// are independent of every other probe's (their random numbers follow probe, pass and slot), so
// given its count its walks are an ordinary sample of fixed size and their mean is unbiased,
// whatever the neighbours drew: a wrong count costs noise, never bias. Quiet probes (empty,
// evenly lit space among quiet neighbours) still stop after the first pass.
#include "lib/checks.glsl"
layout(std430, binding = 6) buffer ProbeNoise {
    float noise_variance_sum;   // sum over probes of their first-pass walk variance; < 0: not set
    float noise_probe_count;    // probes in that sum
    uint walk_passes[];         // per probe: passes it takes (set after the first pass)
};

const float SH_Y00 = 0.28209479177387814;   // Y_0^0 = 1 / (2 sqrt(pi))

// Variance of a probe's walk radiance (v = mean over rgb), from its running means. Variances below
// 1e-6 E[v^2] are float32 rounding of the two running means (walks that all returned the same
// radiance) and count as 0.
float probe_walk_variance(ProbeAccum a)
{
    float mean = (a.channels[0].r + a.channels[0].g + a.channels[0].b)
                 / (3.0 * 4.0 * 3.14159265358979 * SH_Y00);
    float variance = max(a.square_mean - mean * mean, 0.0);
    return variance <= 1e-6 * a.square_mean ? 0.0 : variance;
}

// Whether a probe takes walks in pass `pass_index`: every probe in the first pass (the budgets
// are set when it ends), then those whose budget reaches the pass.
bool probe_takes_pass(uint probe, uint pass_index)
{
    CHECK_INDEX(probe, walk_passes.length(), CHECK_SITE_NOISE_INDEX);
    return noise_variance_sum < 0.0 || pass_index < walk_passes[probe];
}
