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
shared vec3 group_sums[GROUP];

void main()
{
    ivec2 size = textureSize(image, 0);
    ivec2 tile = ivec2(gl_WorkGroupID.xy);
    ivec2 origin = tile * KEEP_MEANS_TILE;
    vec3 sum = vec3(0.0);
    for (int dy = 0; dy < KEEP_MEANS_TILE; dy += GROUP_SIDE) {
        for (int dx = 0; dx < KEEP_MEANS_TILE; dx += GROUP_SIDE) {
            ivec2 p = origin + ivec2(gl_LocalInvocationID.xy) + ivec2(dx, dy);
            if (all(lessThan(p, size))) {
                vec3 value = texelFetch(image, p, 0).rgb;
                sum += usable_only != 0 ? usable_radiance(value, signed_radiance != 0) : value;
            }
        }
    }
    uint lane = gl_LocalInvocationIndex;
    group_sums[lane] = sum;
    memoryBarrierShared();
    barrier();
    for (uint stride = uint(GROUP) / 2u; stride > 0u; stride >>= 1) {
        if (lane < stride)
            group_sums[lane] += group_sums[lane + stride];
        memoryBarrierShared();
        barrier();
    }
    if (lane == 0u) {
        ivec2 pixels = min(ivec2(KEEP_MEANS_TILE), size - origin);
        int tiles_x = (size.x + KEEP_MEANS_TILE - 1) / KEEP_MEANS_TILE;
        tile_mean[tile.x + tiles_x * tile.y] = vec4(group_sums[0] / float(pixels.x * pixels.y), 0.0);
    }
}
