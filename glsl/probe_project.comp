// Probe bake, step 2: project this pass's walks onto SH (equal weights 4 pi / n over the rotated
// Fibonacci set), fold them into each probe's running mean and publish the seven probe textures.
// One work group per probe; the group's invocations share its walks and reduce in shared memory.
// Channel 27 (the sun's transmittance) was written by probe_sun.comp before the first pass.
layout(local_size_x = 64) in;

#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/sh.glsl"
#include "lib/directions.glsl"
#include "lib/probes.glsl"
#include "lib/probe_accum.glsl"

layout(std430, binding = 3) readonly buffer WalkRadiance { vec4 walk_radiance[]; };
// A warm restart's old running means (ProbeGrid.restart(warm=True)): what the textures show is the
// new mean blended with these, weighted as warm_walks walks; 0 (cold, and the last pass): the mean.
layout(std430, binding = 7) readonly buffer PriorAccums { ProbeAccum prior[]; };
uniform float warm_walks;

layout(PROBE_IMAGE_FORMAT, binding = 0) uniform writeonly image3D probe_image0;
#if PROBE_GREY
#if PROBE_SH_ORDER >= 1
layout(PROBE_IMAGE_FORMAT, binding = 1) uniform writeonly image3D probe_image1;
#endif
#if PROBE_SH_ORDER >= 2
layout(PROBE_IMAGE_FORMAT, binding = 2) uniform writeonly image3D probe_image2;
#endif
#else
layout(PROBE_IMAGE_FORMAT, binding = 6) uniform writeonly image3D probe_image6;
#if PROBE_SH_ORDER >= 1
layout(PROBE_IMAGE_FORMAT, binding = 1) uniform writeonly image3D probe_image1;
layout(PROBE_IMAGE_FORMAT, binding = 2) uniform writeonly image3D probe_image2;
#endif
#if PROBE_SH_ORDER >= 2
layout(PROBE_IMAGE_FORMAT, binding = 3) uniform writeonly image3D probe_image3;
layout(PROBE_IMAGE_FORMAT, binding = 4) uniform writeonly image3D probe_image4;
layout(PROBE_IMAGE_FORMAT, binding = 5) uniform writeonly image3D probe_image5;
#endif
#endif

uniform uint first_probe;
uniform uint directions;
uniform uint pass_index;
uniform uint seed;

shared vec3 partial[64][9];
shared uint partial_count[64];
shared float partial_square[64];

void main()
{
    uint tid = gl_LocalInvocationID.x;
    uint probe = first_probe + gl_WorkGroupID.x;
    uint base = gl_WorkGroupID.x * directions;
    vec3 sum[9];
    for (int k = 0; k < 9; ++k)
        sum[k] = vec3(0.0);
    uint count = 0u;
    float square = 0.0;
    for (uint slot = tid; slot < directions; slot += 64u) {
        vec4 walk = walk_radiance[base + slot];
        if (walk.a != 1.0)
            continue;   // dropped (2), or not walked: the probe had converged (3)
        float v = (walk.r + walk.g + walk.b) / 3.0;
        square += v * v;
        float basis[9];
        sh_basis(probe_walk_direction(probe, pass_index, slot, directions, seed), basis);
        for (int k = 0; k < 9; ++k)
            sum[k] += walk.rgb * basis[k];
        count += 1u;
    }
    for (int k = 0; k < 9; ++k)
        partial[tid][k] = sum[k];
    partial_count[tid] = count;
    partial_square[tid] = square;
    barrier();
    for (uint stride = 32u; stride > 0u; stride >>= 1u) {
        if (tid < stride) {
            for (int k = 0; k < 9; ++k)
                partial[tid][k] += partial[tid + stride][k];
            partial_count[tid] += partial_count[tid + stride];
            partial_square[tid] += partial_square[tid + stride];
        }
        barrier();
    }
    if (tid != 0u)
        return;

    ProbeAccum acc = probes[probe];
    if (pass_index == 0u) {
        float sun_transmittance = acc.channels[6].a;   // probe_sun.comp
        for (int t = 0; t < 7; ++t)
            acc.channels[t] = vec4(0.0);
        acc.samples = 0.0;
        acc.square_mean = 0.0;
        acc.channels[6].a = sun_transmittance;
    }
    uint n = partial_count[0];
    float[28] f;
    for (int i = 0; i < 7; ++i) {
        f[4 * i + 0] = acc.channels[i].r;
        f[4 * i + 1] = acc.channels[i].g;
        f[4 * i + 2] = acc.channels[i].b;
        f[4 * i + 3] = acc.channels[i].a;
    }
    vec3 previous_l00 = vec3(f[0], f[1], f[2]);
    if (n > 0u) {
        float total = acc.samples + float(n);
        float weight = float(n) / total;
        for (int k = 0; k < 9; ++k) {
            vec3 projected = partial[0][k] * (4.0 * 3.14159265358979 / float(n));
            for (int c = 0; c < 3; ++c)
                f[3 * k + c] += (projected[c] - f[3 * k + c]) * weight;
        }
        acc.square_mean += (partial_square[0] / float(n) - acc.square_mean) * weight;
        acc.samples = total;
    }
    for (int i = 0; i < 7; ++i)
        acc.channels[i] = vec4(f[4 * i], f[4 * i + 1], f[4 * i + 2], f[4 * i + 3]);
    vec3 l00 = vec3(f[0], f[1], f[2]);
    vec3 delta = l00 - previous_l00;
    acc.change = pass_index == 0u ? 0.0 : dot(delta, delta);
    acc.magnitude = dot(l00, l00);
    probes[probe] = acc;

    vec4 shown[7];
    float w = warm_walks > 0.0 ? warm_walks / (warm_walks + acc.samples) : 0.0;
    for (int i = 0; i < 7; ++i)
        shown[i] = w > 0.0 ? mix(acc.channels[i], prior[probe].channels[i], w) : acc.channels[i];
    // Stored relative to the scene's light (lib/probes.glsl: probe_radiance_scale); channel 27,
    // the sun's transmittance, as it is.
    float to_stored = 1.0 / probe_radiance_scale;
    for (int i = 0; i < 7; ++i) {
        shown[i] = i == 6 ? vec4(shown[i].rgb * to_stored, shown[i].a) : shown[i] * to_stored;
        f[4 * i + 0] = shown[i].r;
        f[4 * i + 1] = shown[i].g;
        f[4 * i + 2] = shown[i].b;
        f[4 * i + 3] = shown[i].a;
    }

    uint nx = uint(probe_grid.x), ny = uint(probe_grid.y);
    ivec3 texel = ivec3(probe % nx, (probe / nx) % ny, probe / (nx * ny));
#if PROBE_GREY
    // r = g = b for grey scenes: store each coefficient's red channel (f[3 k]); lib/probes.glsl
    imageStore(probe_image0, texel, vec4(f[0], f[3], f[6], f[27]));
#if PROBE_SH_ORDER >= 1
    imageStore(probe_image1, texel, vec4(f[9], f[12], f[15], f[18]));
#endif
#if PROBE_SH_ORDER >= 2
    imageStore(probe_image2, texel, vec4(f[21], f[24], 0.0, 0.0));
#endif
#else
    imageStore(probe_image0, texel, shown[0]);
    imageStore(probe_image6, texel, shown[6]);
#if PROBE_SH_ORDER >= 1
    imageStore(probe_image1, texel, shown[1]);
    imageStore(probe_image2, texel, shown[2]);
#endif
#if PROBE_SH_ORDER >= 2
    imageStore(probe_image3, texel, shown[3]);
    imageStore(probe_image4, texel, shown[4]);
    imageStore(probe_image5, texel, shown[5]);
#endif
#endif
}
