// A running mean (rgb the mean, a the count), one value at a time: the raymarcher's frames
// (lib/raymarch.glsl, raymarch_resolve.comp) and the paths' estimates (lib/integrator.glsl).
vec4 running_mean_add(vec4 mean_and_count, vec3 value)
{
    mean_and_count.a += 1.0;
    mean_and_count.rgb += (value - mean_and_count.rgb) / mean_and_count.a;
    return mean_and_count;
}
