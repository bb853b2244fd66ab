// Folds the frames one raymarch.comp dispatch marched into layers (frame_layers > 0) into the
// accumulation's running mean, in frame order: the same sums as adding them one dispatch at a time.
layout(local_size_x = 8, local_size_y = 8) in;
#include "lib/running_mean.glsl"

uniform ivec2 image_size;
uniform int layers;           // frames in frame_values
uniform uint frame_index;     // the first of them; 0 starts the mean afresh
layout(rgba32f, binding = 0) uniform image2D accumulation;
layout(rgba32f, binding = 1) uniform readonly image2DArray frame_values;

void main()
{
    ivec2 pixel = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(pixel, image_size)))
        return;
    vec4 mean_and_count = frame_index == 0u ? vec4(0.0) : imageLoad(accumulation, pixel);
    for (int layer = 0; layer < layers; ++layer)
        mean_and_count = running_mean_add(mean_and_count, imageLoad(frame_values, ivec3(pixel, layer)).rgb);
    imageStore(accumulation, pixel, mean_and_count);
}
