// Majorant per macrocell for empty-space skipping (NumPy twin: app/twins/majorant_grid.py
// majorant_grid); of several channels (MEDIUM_CHANNELS > 1), a bound on their summed sigma_t. Rebuilt whenever the transfer function, density_scale, the crop or the clip plane
// changes: density_scale times the largest opacity of the transfer function over the cell's
// density range. The opacity is piecewise linear in the density, so its maximum over [lo, hi] is
// at lo, at hi, or at a table node between them.
// With a crop or clip plane (lib/clip_region.glsl): a cell with no kept point gets 0 (skipped like
// empty space); a kept cell's points read the density at kept_sample_point, up to a voxel inside
// the crop, so its range is the union of the cells that the clamped points fall in.
layout(local_size_x = 4, local_size_y = 4, local_size_z = 4) in;

#include "lib/medium.glsl"

// RG32F per macrocell: the smallest and largest density trilinear filtering can return inside it
// (already widened for rounding; app/twins/majorant_grid.py density_range_grid).
uniform sampler3D density_range;
uniform ivec3 cells;
uniform float majorant_safety;   // app/twins/majorant_grid.py MAJORANT_SAFETY
// How far beyond its faces (in cells) a cell counts for the crop and clip plane: rounding may put a
// collision a few ulps outside the cell the DDA walks (app/twins/majorant_grid.py CELL_SLACK).
const float CELL_SLACK = 1.0 / 256.0;
layout(r32f, binding = 0) uniform writeonly image3D majorant_out;

// The cells whose density ranges cover the kept points of cell c: first to last (false when no
// point of the cell is kept). Without a crop or clip plane, the cell itself.
bool kept_range_cells(ivec3 c, out ivec3 first, out ivec3 last)
{
    first = c;
    last = c;
    if (clip_region_on == 0)
        return true;
    vec3 cell_size = 2.0 * box_half_extent / vec3(cells);
    vec3 lo = -box_half_extent + vec3(c) * cell_size;
    vec3 hi = lo + cell_size;
    vec3 slack = cell_size * CELL_SLACK;
    if (clip_region_cuts_box(lo - slack, hi + slack))
        return false;
    // Where the kept points of the cell read the density: the cell clamped as the points are. Its
    // own range covers points on its faces (and a little beyond: app/twins/majorant_grid.py
    // SUPPORT_SLACK), so a clamped box ending on a face adds no neighbour.
    vec3 s_lo = kept_sample_point(max(lo, kept_box_min));
    vec3 s_hi = kept_sample_point(min(hi, kept_box_max));
    first = clamp(ivec3(floor((s_lo + box_half_extent) / cell_size)), ivec3(0), cells - 1);
    last = clamp(ivec3(ceil((s_hi + box_half_extent) / cell_size)) - 1, first, cells - 1);
    return true;
}

#if MEDIUM_CHANNELS > 1
// Several channels: density_range holds each channel's least density (RGBA32F, one component a
// channel) and density_range_max each one's largest.
uniform sampler3D density_range_max;

// Each channel's density range over the kept points of cell c (false: no point is kept).
bool kept_density_ranges(ivec3 c, out vec4 range_lo, out vec4 range_hi)
{
    ivec3 first, last;
    range_lo = vec4(1e30);
    range_hi = vec4(-1e30);
    if (!kept_range_cells(c, first, last))
        return false;
    for (int z = first.z; z <= last.z; ++z)
        for (int y = first.y; y <= last.y; ++y)
            for (int x = first.x; x <= last.x; ++x) {
                range_lo = min(range_lo, texelFetch(density_range, ivec3(x, y, z), 0));
                range_hi = max(range_hi, texelFetch(density_range_max, ivec3(x, y, z), 0));
            }
    return true;
}

// Channel ch's largest opacity over densities [lo, hi] (its ends or a table node between them).
float channel_max_alpha(int ch, float lo, float hi)
{
    int n = channel_transfer_size[ch];
    float a = max(channel_transfer_at(ch, lo).a, channel_transfer_at(ch, hi).a);
    float last_node = float(n - 1);
    int i = int(ceil(lo * last_node));
    int last = min(int(floor(hi * last_node)), n - 1);
    for (; i <= last; i += 4) {
        CHECK_INDEX(i, n, CHECK_SITE_TRANSFER_ENTRY);
        a = max(a, CHANNEL_TRANSFER_ENTRY(ch, i).a);
        a = max(a, CHANNEL_TRANSFER_ENTRY(ch, min(i + 1, last)).a);
        a = max(a, CHANNEL_TRANSFER_ENTRY(ch, min(i + 2, last)).a);
        a = max(a, CHANNEL_TRANSFER_ENTRY(ch, min(i + 3, last)).a);
    }
    return a;
}

void main()
{
    ivec3 c = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(c, cells)))
        return;
    vec4 range_lo, range_hi;
    float a = 0.0;
    if (kept_density_ranges(c, range_lo, range_hi)) {
        // A bound on the mixture's opacity (lib/medium.glsl mixed_transfer_at): the sum of each
        // channel's bound over its own range.
        for (int ch = 0; ch < MEDIUM_CHANNELS; ++ch)
            a += channel_on[ch] * channel_max_alpha(ch, clamp(range_lo[ch], 0.0, 1.0),
                                                    clamp(range_hi[ch], 0.0, 1.0));
    }
    CHECK_TEXEL(c, imageSize(majorant_out), CHECK_SITE_IMAGE_TEXEL);
    imageStore(majorant_out, c, vec4(density_scale * a * majorant_safety));
}
#else
// The density range of the points of cell c that are kept (x: least, y: largest; x > y when no
// point of the cell is kept).
vec2 kept_density_range(ivec3 c)
{
    ivec3 first, last;
    if (!kept_range_cells(c, first, last))
        return vec2(1.0, 0.0);
    if (clip_region_on == 0)
        return texelFetch(density_range, c, 0).rg;
    vec2 range = vec2(1e30, -1e30);
    for (int z = first.z; z <= last.z; ++z)
        for (int y = first.y; y <= last.y; ++y)
            for (int x = first.x; x <= last.x; ++x) {
                vec2 r = texelFetch(density_range, ivec3(x, y, z), 0).rg;
                range = vec2(min(range.x, r.x), max(range.y, r.y));
            }
    return range;
}

void main()
{
    ivec3 c = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(c, cells)))
        return;
    vec2 range = kept_density_range(c);
    if (range.x > range.y) {   // no point of the cell is kept: skipped like empty space
        CHECK_TEXEL(c, imageSize(majorant_out), CHECK_SITE_IMAGE_TEXEL);
        imageStore(majorant_out, c, vec4(0.0));
        return;
    }
    float lo = clamp(range.x, 0.0, 1.0);
    float hi = clamp(range.y, 0.0, 1.0);
    float a = max(transfer_at(lo).a, transfer_at(hi).a);
    float last_node = float(transfer_size - 1);
    int i = int(ceil(lo * last_node));
    int last = min(int(floor(hi * last_node)), transfer_size - 1);
    // Four nodes per iteration: at most 1024 iterations for the largest table (4096 rows), well
    // inside llvmpipe's loop limit even at 16 lanes per SIMD batch.
    for (; i <= last; i += 4) {
        CHECK_INDEX(i, transfer_size, CHECK_SITE_TRANSFER_ENTRY);
        a = max(a, TRANSFER_ENTRY(i).a);
        a = max(a, TRANSFER_ENTRY(min(i + 1, last)).a);
        a = max(a, TRANSFER_ENTRY(min(i + 2, last)).a);
        a = max(a, TRANSFER_ENTRY(min(i + 3, last)).a);
    }
    CHECK_TEXEL(c, imageSize(majorant_out), CHECK_SITE_IMAGE_TEXEL);
    imageStore(majorant_out, c, vec4(density_scale * a * majorant_safety));
}
#endif
