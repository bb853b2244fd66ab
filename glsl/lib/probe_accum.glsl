// Each probe's running mean over the bake's passes (app/render/probes.py PROBE_ACCUM_BYTES = 128):
// the 28 channels in texture packing order (lib/probes.glsl), the walks averaged so far, the last
// pass's change, which the host reads for the bake's progress, and the mean square of the walks'
// radiance, from which the adaptive bake estimates each probe's noise (lib/probe_noise.glsl).
struct ProbeAccum {
    vec4 channels[7];   // the 28 channels in texture packing order (see lib/probes.glsl)
    float samples;      // walks averaged so far
    float change;       // squared change of the radiance mean (L00) this pass, summed over rgb
    float magnitude;    // squared L00, summed over rgb
    float square_mean;  // running mean over walks of v^2, v = mean over rgb of a walk's radiance
};
layout(std430, binding = 4) buffer ProbeAccums { ProbeAccum probes[]; };
