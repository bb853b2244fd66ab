// The adaptive bake (lib/probe_noise.glsl), after probe_noise.comp: each probe's passes from its
// neighbours' first-pass walk variance (the mean over the up to 26 around it) and the mean
// variance of the other probes, never its own. One invocation per probe; run once, when the
// first pass ends (the accumulators then hold that pass alone).
//
// The neighbours' mean rather than their largest: measured on llvmpipe (cloud 32^3, 12^3 probes
// x 256 walks, 6 seeds), both unbiased, the largest took 86% of the walks for the same probe
// variance per walk as a full bake, the mean 63% for 5% less variance per walk (anisotropic
// cloud; the thick cloud 89%, 3% less).
layout(local_size_x = 64) in;

#include "lib/probe_accum.glsl"
#include "lib/probe_noise.glsl"

uniform ivec3 probe_grid;
uniform float adaptive_factor;   // the noise target's scale (RenderSettings.walk_adaptive)
uniform float walks_asked;       // walks per probe of the whole bake (N)
uniform uint directions;         // walks per pass
uniform uint passes_total;

void main()
{
    uint probe = gl_GlobalInvocationID.x;
    uint count = uint(probe_grid.x * probe_grid.y * probe_grid.z);
    if (probe >= count)
        return;
    ivec3 n = probe_grid;
    ivec3 ijk = ivec3(probe % uint(n.x), (probe / uint(n.x)) % uint(n.y), probe / uint(n.x * n.y));
    float neighbour_sum = 0.0;
    float neighbours = 0.0;
    for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                ivec3 q = ijk + ivec3(dx, dy, dz);
                if ((dx == 0 && dy == 0 && dz == 0) || any(lessThan(q, ivec3(0)))
                    || any(greaterThanEqual(q, n)))
                    continue;
                neighbour_sum += probe_walk_variance(probes[uint(q.x + n.x * (q.y + n.y * q.z))]);
                neighbours += 1.0;
            }
    // the mean over every other probe (its own variance taken out of the sum)
    float others = noise_probe_count - 1.0;
    float mean_others = others > 0.0
        ? max(noise_variance_sum - probe_walk_variance(probes[probe]), 0.0) / others : 0.0;
    uint passes = passes_total;   // no neighbours (a single probe): every walk
    if (neighbours > 0.0) {
        float neighbour = neighbour_sum / neighbours;
        if (mean_others > 0.0) {
            float walks = walks_asked * neighbour / (adaptive_factor * adaptive_factor * mean_others);
            passes = uint(clamp(ceil(walks / float(directions)), 1.0, float(passes_total)));
        } else {
            passes = 1u;   // every other probe's walks agree: nothing more to learn here
        }
    }
    CHECK_INDEX(probe, walk_passes.length(), CHECK_SITE_NOISE_INDEX);
    CHECK_INDEX(probe, probes.length(), CHECK_SITE_PROBE_INDEX);
    CHECK_TRUE(passes >= 1u && passes <= passes_total, CHECK_SITE_WALK_BUDGET);
    walk_passes[probe] = passes;
}
