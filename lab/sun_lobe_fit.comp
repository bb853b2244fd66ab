// Which lobe shape a scene's probes should hold (lab/sun_lobe_fit.py, which chooses from these
// numbers; NumPy twin: lab/sun_lobe_fit.py lobe_amplitudes; outside the package: an experiment's,
// compiled with the package's glsl/lib). One invocation per probe of a
// pilot bake's pass, whose walks are in walk_radiance (probe_walks.comp): for each candidate h
// (the lobe HG_h about the sun's direction, lib/sun_lobe.glsl) the lobe's amplitude as the bake
// estimates it from these walks, a = 4 pi / N sum L_i sun_lobe_basis(mu_i) per colour, and N.
// Two passes (independent random rotations of the walks' direction set) give two independent
// estimates; halves of one pass would not be (the two halves of a Fibonacci set are
// complementary: their quadrature errors cancel, so their product is biased low).
layout(local_size_x = 64) in;

#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/sh.glsl"
#include "lib/directions.glsl"
#include "lib/probes.glsl"

#ifndef SUN_LOBE_CANDIDATES
#define SUN_LOBE_CANDIDATES 3
#endif

layout(std430, binding = 3) readonly buffer WalkRadiance { vec4 walk_radiance[]; };
// [first_output + probe * SUN_LOBE_CANDIDATES + k]: rgb the amplitude, a the walks it used
layout(std430, binding = 0) writeonly buffer LobeAmplitudes { vec4 lobe_amplitudes[]; };

uniform uint probe_count;
uniform uint directions;     // walks per probe of the pass
uniform uint pass_index;
uniform uint seed;           // the pilot bake's seed (its walk directions)
uniform uint first_output;
uniform float candidate_h[SUN_LOBE_CANDIDATES];

void main()
{
    uint probe = gl_GlobalInvocationID.x;
    if (probe >= probe_count)
        return;
    float g = sun_lobe_phase_g;
    vec3 sum[SUN_LOBE_CANDIDATES];
    for (int k = 0; k < SUN_LOBE_CANDIDATES; ++k)
        sum[k] = vec3(0.0);
    float count = 0.0;
    for (uint slot = 0u; slot < directions; ++slot) {
        vec4 walk = walk_radiance[probe * directions + slot];
        if (walk.a != 1.0)
            continue;   // dropped
        float mu = dot(probe_walk_direction(probe, pass_index, slot, directions, seed),
                       sun_direction);
        for (int k = 0; k < SUN_LOBE_CANDIDATES; ++k)
            sum[k] += walk.rgb * sun_lobe_basis(mu, g, candidate_h[k], PROBE_SH_ORDER);
        count += 1.0;
    }
    for (int k = 0; k < SUN_LOBE_CANDIDATES; ++k) {
        vec3 a = count > 0.0 ? 4.0 * PI * sum[k] / count : vec3(0.0);
        lobe_amplitudes[first_output + probe * uint(SUN_LOBE_CANDIDATES) + uint(k)] = vec4(a, count);
    }
}
