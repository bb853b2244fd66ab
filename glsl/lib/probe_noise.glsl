// The adaptive bake (walks per probe set by each probe's own noise): a probe gets no more walks
// once the standard error of its mean radiance is at most the noise target.
//
// Each walk's radiance v (mean over rgb) is one sample; a probe's walks have variance
// var = E[v^2] - E[v]^2, estimated from its running means (ProbeAccum: E[v] from L00, E[v^2] from
// square_mean), and its mean over n walks has standard error^2 var / n (an upper bound: the
// stratified directions of a pass do better than independent ones). After the first pass,
// probe_noise.comp sets the target^2 to factor^2 x (the mean over probes of var) / N, where N is the
// walks per probe asked for: what N walks give a probe of average noise. Probes noisier than the
// average take all N walks as before; quieter ones (empty, evenly lit space) stop early, at
// n = N var / (factor^2 mean var). Probes whose estimate stopped moving get no more walks.
layout(std430, binding = 6) buffer ProbeNoise {
    float noise_target_squared;   // < 0: not set (every probe takes walks)
    float mean_walk_variance;
};

const float SH_Y00 = 0.28209479177387814;   // Y_0^0 = 1 / (2 sqrt(pi))

// Variance of a probe's walk radiance (v = mean over rgb), from its running means.
float probe_walk_variance(ProbeAccum a)
{
    float mean = (a.channels[0].r + a.channels[0].g + a.channels[0].b)
                 / (3.0 * 4.0 * 3.14159265358979 * SH_Y00);
    return max(a.square_mean - mean * mean, 0.0);
}

// Variances below 1e-6 E[v^2] are float32 rounding of the two running means (walks that all
// returned the same radiance) and count as 0.
bool probe_converged(ProbeAccum a)
{
    float variance = probe_walk_variance(a);
    return noise_target_squared >= 0.0 && a.samples > 0.0
           && (variance <= noise_target_squared * a.samples || variance <= 1e-6 * a.square_mean);
}
