// The raymarcher as a compute pass: one invocation per pixel and frame. With frame_layers 0 a
// dispatch adds frame frame_index to the accumulation. Otherwise it marches gl_NumWorkGroups.z
// frames at once (frame_index + layer), each into its layer of frame_values, and
// raymarch_resolve.comp folds them into the accumulation in frame order: a small image fills a
// large GPU only with several frames in flight (app/rendering/methods/raymarch.py LAYER_PIXELS). A uniform,
// not a define, so that one program (one compile) serves both.
// The work group's shape comes from app/rendering/methods/raymarch.py (group_shape: 8 x 4 without
// surfaces, 8 x 8 with them, as measured); the pixels' arithmetic does not depend on it.
#ifndef RAYMARCH_GROUP_X
#define RAYMARCH_GROUP_X 8
#define RAYMARCH_GROUP_Y 8
#endif
layout(local_size_x = RAYMARCH_GROUP_X, local_size_y = RAYMARCH_GROUP_Y) in;
#include "raymarch_common.glsl"

uniform int frame_layers;
layout(rgba32f, binding = 1) uniform writeonly image2DArray frame_values;
// The first pixel (column, row) of a frame_layers 0 dispatch: a frame that takes longer than a
// viewer's frame may is marched in bands of work groups over several (app/rendering/budgets/sample_bands.py).
uniform ivec2 tile_offset;

void main()
{
    ivec2 pixel = ivec2(gl_GlobalInvocationID.xy);
    if (frame_layers == 0) {
        raymarch_pixel(pixel + tile_offset);
        return;
    }
    if (any(greaterThanEqual(pixel, image_size)))
        return;
    uint layer = gl_GlobalInvocationID.z;
    CHECK_TEXEL(ivec3(pixel, int(layer)), imageSize(frame_values), CHECK_SITE_IMAGE_TEXEL);
    imageStore(frame_values, ivec3(pixel, int(layer)), vec4(raymarch_frame(pixel, frame_index + layer), 0.0));
}
