// The denoiser's guides (lib/denoise_guides.glsl) as a compute pass: one invocation per pixel and
// frame; each frame's jittered ray (the raymarcher's sub-pixel position and start) adds to the
// running means of the two images, so that the guides are anti-aliased as the colour is.
layout(local_size_x = 8, local_size_y = 8) in;
#include "lib/rng.glsl"
#include "lib/camera.glsl"
#include "lib/medium.glsl"
#include "lib/running_mean.glsl"
uniform float raymarch_step;    // world units
uniform float gradient_step;    // world units
uniform uint frame_index;       // 0 starts the means afresh
uniform uint seed;
#include "lib/denoise_guides.glsl"

layout(rgba32f, binding = 0) uniform image2D albedo_image;
layout(rgba32f, binding = 1) uniform image2D normal_image;

void main()
{
    ivec2 pixel = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(pixel, image_size)))
        return;
    uint rng = rng_seed(uint(pixel.y * image_size.x + pixel.x), frame_index, seed);
    vec2 sub = vec2(rng_next(rng), rng_next(rng));
    vec3 albedo_guide, normal_guide;
    guide_march(camera_eye, camera_ray_direction(vec2(pixel) + sub), rng_next(rng),
                albedo_guide, normal_guide);
    CHECK_TEXEL(pixel, imageSize(albedo_image), CHECK_SITE_IMAGE_TEXEL);
    vec4 a = frame_index == 0u ? vec4(0.0) : imageLoad(albedo_image, pixel);
    vec4 b = frame_index == 0u ? vec4(0.0) : imageLoad(normal_image, pixel);
    imageStore(albedo_image, pixel, running_mean_add(a, albedo_guide));
    imageStore(normal_image, pixel, running_mean_add(b, normal_guide));
}
