// Each probe's running mean over the bake's passes (app/rendering/probes/bake.py accum_bytes): the colour
// packing's channels (lib/probe_packing.glsl; 28 up to order 2, 52 at order 3, 76 at order 4),
// the walks averaged so far, the last pass's change, which the host reads for the bake's progress,
// and the mean square of the walks' radiance, from which the adaptive bake estimates each probe's
// noise (lib/probe_noise.glsl).
#include "lib/probe_packing.glsl"
struct ProbeAccum {
    vec4 channels[PROBE_COLOUR_TEXTURES];   // the colour packing's channels
    float samples;      // walks averaged so far
    float change;       // squared change of the radiance mean (L00) this pass, summed over rgb
    float magnitude;    // squared L00, summed over rgb
    float square_mean;  // running mean over walks of v^2, v = mean over rgb of a walk's radiance
};
layout(std430, binding = 4) buffer ProbeAccums { ProbeAccum probes[]; };
