// Reference path tracer: one pass adds samples_per_pass samples per pixel to the running mean.
layout(local_size_x = 8, local_size_y = 8) in;

#include "lib/rng.glsl"
#include "lib/camera.glsl"
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/phase.glsl"
#include "lib/tracking.glsl"
#include "lib/integrator.glsl"

layout(rgba32f, binding = 0) uniform image2D accumulation;  // rgb: running mean, a: sample count
uniform uint seed;
uniform uint first_sample;      // index of this pass's first sample (keys the random streams)
uniform int samples_per_pass;

void main()
{
    ivec2 pixel = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(pixel, image_size)))
        return;
    uint key = uint(pixel.y * image_size.x + pixel.x);
    vec3 sum = vec3(0.0);
    uint count = 0u;
    for (int s = 0; s < samples_per_pass; ++s) {
        uint rng = rng_seed(key, first_sample + uint(s), seed);
        vec2 jitter = vec2(rng_next(rng), rng_next(rng));  // box filter over the pixel's area
        vec3 direction = camera_ray_direction(vec2(pixel) + jitter);
        vec3 radiance;
        bool valid = path_radiance(camera_eye, direction, rng, radiance);
        accumulate_sample(sum, count, radiance, valid);
    }
    vec4 previous = imageLoad(accumulation, pixel);
    float n_before = first_sample == 0u ? 0.0 : previous.a;
    float n_after = n_before + float(count);
    vec3 mean = first_sample == 0u ? vec3(0.0) : previous.rgb;
    if (count > 0u)
        mean += (sum / float(count) - mean) * (float(count) / n_after);  // stable running mean
    imageStore(accumulation, pixel, vec4(mean, n_after));
}
