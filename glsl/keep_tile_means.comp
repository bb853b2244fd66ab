// The filtered image given back the raw image's tile means (app/rendering/denoise/kept_means.py; NumPy
// twin keep_block_means in app/rendering/denoise/filter.py, with _cell_field and _apply_cells). Per
// tile, from the raw image's means and the filtered image's own (tile_means.comp, the latter of
// the usable values): where the tile gained energy (raw < own) a scale raw / own, where it lost
// the difference added; a signed image (signed_radiance) has the difference throughout. That
// correction is interpolated linearly between tile centres at the centre of each
// KEEP_MEANS_CELL x KEEP_MEANS_CELL-pixel cell and held constant over the cell: one workgroup a
// cell. The result is made usable again (finite and, unless signed, non-negative): this pass is
// the check of the filter's output as well.
#if !defined(KEEP_MEANS_TILE) || !defined(KEEP_MEANS_CELL)
#error "KEEP_MEANS_TILE and KEEP_MEANS_CELL (KEEP_MEANS_BLOCK, KEEP_MEANS_CELL), defined by the host"
#endif
layout(local_size_x = KEEP_MEANS_CELL, local_size_y = KEEP_MEANS_CELL) in;
#include "lib/usable_radiance.glsl"

uniform sampler2D filtered;     // the filter's output (RGB32F), texel (x, y): pixel x of row y
uniform int signed_radiance;    // 1: the filtered image may dip below zero
layout(std430, binding = 0) readonly buffer RawTileMeans { vec4 raw_tile_mean[]; };
layout(std430, binding = 1) readonly buffer OwnTileMeans { vec4 own_tile_mean[]; };
layout(rgba32f, binding = 0) writeonly uniform image2D restored;

// The two tiles whose centres bracket a cell's centre along one axis, and the weight of the
// second (_cell_field's weights: the centre ((cell + 0.5) * cell side) / tile side - 0.5 in tile
// units, clamped to the tiles there are).
void bracketing_tiles(int cell_index, int tiles, out int lo, out int hi, out float fraction)
{
    float centre = (float(cell_index) + 0.5) * float(KEEP_MEANS_CELL) / float(KEEP_MEANS_TILE) - 0.5;
    lo = clamp(int(floor(centre)), 0, tiles - 1);
    hi = min(lo + 1, tiles - 1);
    fraction = clamp(centre - float(lo), 0.0, 1.0);
}

// One tile's correction: filtered * scale + add.
void tile_correction(int tile, out vec3 scale, out vec3 add)
{
    vec3 raw = raw_tile_mean[tile].rgb;
    vec3 own = own_tile_mean[tile].rgb;
    vec3 difference = raw - own;
    if (signed_radiance != 0) {
        scale = vec3(1.0);
        add = difference;
        return;
    }
    bvec3 gained = lessThan(difference, vec3(0.0));
    vec3 ratio = raw / mix(vec3(1.0), own, greaterThan(own, vec3(0.0)));
    scale = mix(vec3(1.0), ratio, gained);
    add = mix(difference, vec3(0.0), gained);
}

void main()
{
    ivec2 size = textureSize(filtered, 0);
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, size)))
        return;
    ivec2 tiles = (size + KEEP_MEANS_TILE - 1) / KEEP_MEANS_TILE;
    ivec2 cell = ivec2(gl_WorkGroupID.xy);
    int x0, x1, y0, y1;
    float fx, fy;
    bracketing_tiles(cell.x, tiles.x, x0, x1, fx);
    bracketing_tiles(cell.y, tiles.y, y0, y1, fy);
    vec3 s00, s01, s10, s11, a00, a01, a10, a11;   // s_yx: (row y0 or y1, column x0 or x1)
    tile_correction(x0 + tiles.x * y0, s00, a00);
    tile_correction(x1 + tiles.x * y0, s01, a01);
    tile_correction(x0 + tiles.x * y1, s10, a10);
    tile_correction(x1 + tiles.x * y1, s11, a11);
    // along x first, then y, as _cell_field
    vec3 scale = (s00 * (1.0 - fx) + s01 * fx) * (1.0 - fy) + (s10 * (1.0 - fx) + s11 * fx) * fy;
    vec3 add = (a00 * (1.0 - fx) + a01 * fx) * (1.0 - fy) + (a10 * (1.0 - fx) + a11 * fx) * fy;
    bool signed_values = signed_radiance != 0;
    vec3 value = usable_radiance(texelFetch(filtered, p, 0).rgb, signed_values);
    imageStore(restored, p, vec4(usable_radiance(value * scale + add, signed_values), 1.0));
}
