// Publishing the probes: each probe's running mean (lib/probe_accum.glsl), blended with a warm
// restart's old one, scaled to what the textures store (lib/probes.glsl probe_radiance_scale) and
// written into the texels of the textures this build has (lib/probe_packing.glsl), at most
// PROBE_IMAGE_LIMIT of them per dispatch (OpenGL 4.3 guarantees 8 image units to a compute shader):
// slots PROBE_PUBLISH_FIRST .. PROBE_PUBLISH_FIRST + PROBE_PUBLISH_COUNT - 1, slot i at image unit
// i - PROBE_PUBLISH_FIRST. probe_project.comp publishes slots 0 .. 7 as it folds in a pass (one
// invocation a texture); probe_publish.comp the rest (orders 3 and 4: 13 and 19 textures).
// PROBE_IMAGE_LIMIT comes from app/rendering/probes/bake.py, which splits the dispatches by it.
#ifndef PROBE_IMAGE_LIMIT
#error "PROBE_IMAGE_LIMIT: set by app/rendering/probes/bake.py (ProbeGrid), which splits the dispatches by it"
#endif
#ifndef PROBE_PUBLISH_FIRST
#define PROBE_PUBLISH_FIRST 0
#endif
#if PROBE_TEXTURE_COUNT - PROBE_PUBLISH_FIRST > PROBE_IMAGE_LIMIT
#define PROBE_PUBLISH_COUNT PROBE_IMAGE_LIMIT
#else
#define PROBE_PUBLISH_COUNT (PROBE_TEXTURE_COUNT - PROBE_PUBLISH_FIRST)
#endif

layout(PROBE_IMAGE_FORMAT, binding = 0) uniform writeonly image3D probe_images[PROBE_PUBLISH_COUNT];

// A warm restart's old running means (ProbeGrid.restart(warm=True)): what the textures show is the
// new mean blended with these, weighted as warm_walks walks; 0 (cold, and the last pass): the mean.
// Binding 0, which the walks do not use. It was 7, TrackingStats' binding: bound for the bake, it
// replaced the walks' stats buffer, so a walk dropped as truncated or non-finite was counted into
// the first word of probe 0's running mean (or of its warm prior) instead of the stats.
layout(std430, binding = 0) readonly buffer PriorAccums { ProbeAccum prior[]; };
uniform float warm_walks;

// Texture slot PROBE_PUBLISH_FIRST + i of `probe`, whose running means (PROBE_MEAN(probe, f),
// channel f of the colour packing: the buffer's, or probe_project.comp's shared copy) average
// `samples` walks.
#ifndef PROBE_MEAN
#define PROBE_MEAN(probe, f) probes[probe].channels[(f) / 4][(f) % 4]
#endif
void probe_publish_texture(uint probe, int i, float samples)
{
    float w = warm_walks > 0.0 ? warm_walks / (warm_walks + samples) : 0.0;
    float to_stored = 1.0 / probe_radiance_scale;
    ivec3 texel = ivec3(probe_ijk(probe));
    int number = probe_texture_number(PROBE_PUBLISH_FIRST + i);
    vec4 value = vec4(0.0);
    for (int component = 0; component < 4; ++component) {
#if PROBE_GREY
        // r = g = b for grey scenes: each coefficient's red channel
        int f = probe_grey_source(4 * number + component);
#else
        int f = 4 * number + component;
#endif
        if (f < 0)
            continue;
        CHECK_INDEX(probe, probes.length(), CHECK_SITE_PROBE_INDEX);
        float shown = PROBE_MEAN(probe, f);
        if (w > 0.0)
            CHECK_INDEX(probe, prior.length(), CHECK_SITE_PROBE_INDEX);
        if (w > 0.0)
            shown = mix(shown, prior[probe].channels[f / 4][f % 4], w);
        if (f != PROBE_SUN_CHANNEL)   // the sun's transmittance is stored as it is
            shown *= to_stored;
        value[component] = shown;
    }
    CHECK_TEXEL(texel, imageSize(probe_images[i]), CHECK_SITE_IMAGE_TEXEL);
    imageStore(probe_images[i], texel, value);
}
