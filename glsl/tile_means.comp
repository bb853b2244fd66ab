// An image's mean over each KEEP_MEANS_TILE x KEEP_MEANS_TILE-pixel tile (app/rendering/denoise/kept_means.py;
// NumPy twin _block_means in app/rendering/denoise/filter.py): one workgroup a tile, each invocation
// summing the pixels of the tile that fall on it, then the group's sums added in shared memory.
// Tiles at the right and bottom edges average the pixels they have. The image is read with
// texelFetch, so an RGBA32F accumulation and an RGB32F texture both serve (rgb: linear radiance;
// texel (x, y) is pixel x of row y, row 0 at the top).
//
// As read (usable_only 0), a non-finite pixel makes its tile's mean non-finite: the host reads
// the means back and looks for that. With usable_only, each pixel is taken as usable_radiance
// makes it (the filter's output, as keep_tile_means.comp corrects it).
//
// w: the tile's least component value, so that a signed image's filter job learns whether it has
// a negative pixel from the means alone (no host pass over the image; NaN aside: a NaN tile's
// mean is not finite and the host then looks itself).
#if !defined(KEEP_MEANS_TILE)
#error "KEEP_MEANS_TILE: the tile's side (KEEP_MEANS_BLOCK), defined by the host"
#endif
#define GROUP_SIDE 16
#define GROUP (GROUP_SIDE * GROUP_SIDE)
layout(local_size_x = GROUP_SIDE, local_size_y = GROUP_SIDE) in;
#include "lib/usable_radiance.glsl"

uniform sampler2D image;
uniform int usable_only;        // 1: each pixel as usable_radiance makes it
uniform int signed_radiance;    // with usable_only: negative values kept
// rgb: the tile's mean; tile (x, y) at x + tiles_x * y
layout(std430, binding = 0) writeonly buffer TileMeans { vec4 tile_mean[]; };
shared vec4 group_sums[GROUP];   // rgb: sums; w: the least component

void main()
{
    ivec2 size = textureSize(image, 0);
    ivec2 tile = ivec2(gl_WorkGroupID.xy);
    ivec2 origin = tile * KEEP_MEANS_TILE;
    vec3 sum = vec3(0.0);
    float least = 3.402823e38;
    for (int dy = 0; dy < KEEP_MEANS_TILE; dy += GROUP_SIDE) {
        for (int dx = 0; dx < KEEP_MEANS_TILE; dx += GROUP_SIDE) {
            ivec2 p = origin + ivec2(gl_LocalInvocationID.xy) + ivec2(dx, dy);
            if (all(lessThan(p, size))) {
                vec3 value = texelFetch(image, p, 0).rgb;
                if (usable_only != 0)
                    value = usable_radiance(value, signed_radiance != 0);
                sum += value;
                least = min(least, min(min(value.r, value.g), value.b));
            }
        }
    }
    uint lane = gl_LocalInvocationIndex;
    group_sums[lane] = vec4(sum, least);
    memoryBarrierShared();
    barrier();
    for (uint stride = uint(GROUP) / 2u; stride > 0u; stride >>= 1) {
        if (lane < stride) {
            vec4 other = group_sums[lane + stride];
            group_sums[lane] = vec4(group_sums[lane].rgb + other.rgb,
                                    min(group_sums[lane].w, other.w));
        }
        memoryBarrierShared();
        barrier();
    }
    if (lane == 0u) {
        ivec2 pixels = min(ivec2(KEEP_MEANS_TILE), size - origin);
        int tiles_x = (size.x + KEEP_MEANS_TILE - 1) / KEEP_MEANS_TILE;
        tile_mean[tile.x + tiles_x * tile.y] = vec4(group_sums[0].rgb / float(pixels.x * pixels.y),
                                                    group_sums[0].w);
    }
}
