// A pixel's running mean over frames (rgb the mean, a the count), one frame at a time: the
// raymarcher's accumulation image (lib/raymarch.glsl, raymarch_resolve.comp).
vec4 running_mean_add(vec4 mean_and_count, vec3 value)
{
    mean_and_count.a += 1.0;
    mean_and_count.rgb += (value - mean_and_count.rgb) / mean_and_count.a;
    return mean_and_count;
}
