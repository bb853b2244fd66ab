// A bricked volume (VOLUME_BRICKED 1; NumPy twin: app/twins/brick_pool.py): the volume cut into
// bricks of brick_size (B) voxels per axis, each non-constant brick stored in one slot of an
// atlas texture with a one-voxel apron on every side ((B + 2)^3 texels a slot: the neighbours'
// voxels, or the edge voxel repeated at the volume's faces), and a page table (R32UI, one texel a
// brick) holding the brick's slot, or BRICK_CONSTANT | k for a brick whose voxels and apron all
// hold constant k (brick_constants, RGBA32F, a texel a constant; k = 0 is vacuum).
//
// bricked_sample(uvw) is the whole texture's texture(volume, uvw): for every point of brick b the
// two voxels per axis that trilinear filtering blends lie in [b B - 1, b B + B], inside the slot's
// apron, and the filter's fractions are the whole texture's (the coordinates differ by an integer
// number of texels; only their float rounding differs), so the seams between bricks are the whole
// texture's filtering. bricked_voxel(v) is texelFetch(volume, v, 0).
//
// Mixed levels (BRICK_LEVELS > 1): the pool holds bricks of several levels of one pyramid, level
// 0 the finest (its dims brick_volume_dims: the volume's), each coarser level with its own page
// table stacked above level 0's along z (brick_level_table_z). A level-0 entry BRICK_REDIRECT |
// level sends its brick's points to that level: there the point's coordinate is uvw times that
// level's dims, the brick holding it is looked up in that level's table, and sampled as above. The
// host makes every brick such a point lands in resident (or constant); its apron makes the
// filtering inside it that level's own. The medium is then level 0's where level 0 is resident and
// a coarser level's elsewhere, the same for every method.
//
// The checking build (SHADER_CHECKS, lib/checks.glsl) reads brick_of_slot (the brick each slot
// holds, level << 28 | its linear index in its level, written by the host; 0xffffffff for a free
// slot) and counts CHECK_SITE_PAGE_MISS where the page table sends a brick to a slot holding
// another brick or none, to a constant past the table of constants, or to a level it lacks.
#include "lib/checks.glsl"
#if !defined(VOLUME_BRICKED)
#define VOLUME_BRICKED 0
#endif
#if !defined(BRICK_LEVELS)
#define BRICK_LEVELS 1
#endif
#if VOLUME_BRICKED
uniform sampler3D brick_atlas;        // linear, clamped: the slots, (B + 2)^3 texels each
uniform usampler3D brick_table;       // a texel a brick: its slot, or BRICK_CONSTANT | constant
uniform sampler2D brick_constants;    // constant k at (k % width, k / width)
uniform ivec3 brick_volume_dims;      // the volume's voxels per axis
uniform ivec3 brick_counts;           // bricks per axis
uniform int brick_size;               // B
uniform ivec3 brick_slots;            // slots per axis of the atlas
const uint BRICK_CONSTANT = 0x80000000u;
const uint BRICK_REDIRECT = 0x40000000u;  // level 0's table only: | the level that holds it
#if BRICK_LEVELS > 1
uniform ivec3 brick_level_dims[BRICK_LEVELS];     // voxels per axis of each level (0: the volume's)
uniform ivec3 brick_level_counts[BRICK_LEVELS];   // bricks per axis of each level
uniform int brick_level_table_z[BRICK_LEVELS];    // the first z of each level's table
#endif
#if defined(SHADER_CHECKS)
#ifndef BRICK_SLOTS_BINDING
#define BRICK_SLOTS_BINDING 10
#endif
uniform int brick_constant_count;     // constants in brick_constants
layout(std430, binding = BRICK_SLOTS_BINDING) readonly buffer BrickSlots {
    uint brick_of_slot[];             // the linear brick index (x + bx (y + by z)) a slot holds
};
#endif

// The page table's entry of brick b of level `level` (the checking build checks it against
// brick_of_slot).
uint brick_entry(ivec3 b, int level)
{
#if BRICK_LEVELS > 1
    ivec3 counts = brick_level_counts[level];
    uint e = texelFetch(brick_table, b + ivec3(0, 0, brick_level_table_z[level]), 0).r;
#else
    ivec3 counts = brick_counts;
    uint e = texelFetch(brick_table, b, 0).r;
#endif
#if defined(SHADER_CHECKS)
    if ((e & BRICK_CONSTANT) != 0u) {
        CHECK_INDEX(e & ~BRICK_CONSTANT, brick_constant_count, CHECK_SITE_PAGE_MISS);
    } else if ((e & BRICK_REDIRECT) != 0u) {
        CHECK_TRUE(level == 0 && int(e & ~BRICK_REDIRECT) < BRICK_LEVELS
                   && int(e & ~BRICK_REDIRECT) > 0, CHECK_SITE_PAGE_MISS);
    } else {
        uint brick = (uint(level) << 28) | uint(b.x + counts.x * (b.y + counts.y * b.z));
        uint slots = uint(brick_slots.x * brick_slots.y * brick_slots.z);
        CHECK_TRUE(e < slots && brick_of_slot[min(e, slots - 1u)] == brick, CHECK_SITE_PAGE_MISS);
    }
#endif
    return e;
}

#if BRICK_LEVELS > 1
// The level a level-0 entry sends its points to, else -1.
int brick_redirect(uint e)
{
    return (e & (BRICK_CONSTANT | BRICK_REDIRECT)) == BRICK_REDIRECT
        ? clamp(int(e & ~BRICK_REDIRECT), 1, BRICK_LEVELS - 1) : -1;
}
#endif

// The first texel (the apron's corner) of slot `slot` in the atlas.
ivec3 brick_slot_origin(uint slot)
{
    uint sx = uint(brick_slots.x), sy = uint(brick_slots.y);
    return ivec3(int(slot % sx), int((slot / sx) % sy), int(slot / (sx * sy))) * (brick_size + 2);
}

vec4 brick_constant(uint e)
{
    int k = int(e & ~BRICK_CONSTANT);
    int w = textureSize(brick_constants, 0).x;
    return texelFetch(brick_constants, ivec2(k % w, k / w), 0);
}

// texture(volume, uvw) of the whole volume (cell-centred, trilinear, clamped to the edge voxel);
// with mixed levels, of the level that holds uvw's brick.
vec4 bricked_sample(vec3 uvw)
{
    // t in voxels from the volume's low face; clamping to the box changes no value (beyond the
    // outermost voxel centres the filter returns the edge voxel) and keeps every point inside a
    // brick's apron.
    vec3 dims = vec3(brick_volume_dims);
    vec3 t = clamp(uvw * dims, vec3(0.0), dims);
    ivec3 b = clamp(ivec3(floor(t / float(brick_size))), ivec3(0), brick_counts - 1);
    uint e = brick_entry(b, 0);
#if BRICK_LEVELS > 1
    int level = brick_redirect(e);
    if (level > 0) {
        vec3 level_dims = vec3(brick_level_dims[level]);
        t = clamp(uvw * level_dims, vec3(0.0), level_dims);
        b = clamp(ivec3(floor(t / float(brick_size))), ivec3(0), brick_level_counts[level] - 1);
        e = brick_entry(b, level);
    }
#endif
    if ((e & BRICK_CONSTANT) != 0u)
        return brick_constant(e);
    // the voxel coordinate s = t - 0.5 in the brick (its voxels at 0 .. B - 1), one texel past
    // the apron, and half a texel to the texel's centre: the atlas coordinate of s.
    vec3 texel = vec3(brick_slot_origin(e)) + 1.5 + (t - 0.5 - vec3(b * brick_size));
    return texture(brick_atlas, texel / vec3(textureSize(brick_atlas, 0)));
}

// texelFetch(volume, v, 0) of the whole volume (v inside it; with mixed levels, of level 0, whose
// bricks at v must be resident).
vec4 bricked_voxel(ivec3 v)
{
    ivec3 b = clamp(v / brick_size, ivec3(0), brick_counts - 1);
    uint e = brick_entry(b, 0);
    if ((e & BRICK_CONSTANT) != 0u)
        return brick_constant(e);
    return texelFetch(brick_atlas, brick_slot_origin(e) + 1 + v - b * brick_size, 0);
}

// Least and largest values the medium takes near voxel v's centre (visible_region.comp), such
// that over a cell between voxel centres the union of its 8 corners' ranges holds every value
// the medium takes in it: with one level, the voxel itself; with mixed levels, in a coarser
// level's brick the 2 x 2 x 2 voxels of that level the filter blends at v's centre (a cell
// spans at most half a voxel of a coarser level), and on the faces of a level-0 brick the voxel
// and its 26 neighbours.
void bricked_voxel_range(ivec3 v, out vec4 lo, out vec4 hi)
{
#if BRICK_LEVELS > 1
    ivec3 b = clamp(v / brick_size, ivec3(0), brick_counts - 1);
    int level = brick_redirect(brick_entry(b, 0));
    if (level > 0) {
        vec3 t = (vec3(v) + 0.5) * vec3(brick_level_dims[level]) / vec3(brick_volume_dims);
        ivec3 lb = clamp(ivec3(floor(t / float(brick_size))), ivec3(0),
                         brick_level_counts[level] - 1);
        uint e = brick_entry(lb, level);
        if ((e & BRICK_CONSTANT) != 0u) {
            lo = hi = brick_constant(e);
            return;
        }
        ivec3 first = ivec3(floor(t - 0.5));
        ivec3 slot = brick_slot_origin(e) + 1 - lb * brick_size;
        lo = vec4(3.0e38);
        hi = vec4(-3.0e38);
        for (int k = 0; k < 8; ++k) {
            ivec3 w = first + ivec3(k & 1, (k >> 1) & 1, (k >> 2) & 1);
            w = clamp(w, lb * brick_size - 1, lb * brick_size + brick_size);
            vec4 d = texelFetch(brick_atlas, slot + w, 0);
            lo = min(lo, d);
            hi = max(hi, d);
        }
        return;
    }
    // a level-0 voxel on its brick's faces: with its neighbours from the apron, since a cell
    // across the face is level 0's filtering of them on this side, whatever level the
    // neighbouring brick reads
    uint e = brick_entry(b, 0);
    ivec3 local = v - b * brick_size;
    if ((e & BRICK_CONSTANT) == 0u
        && (any(equal(local, ivec3(0))) || any(equal(local, ivec3(brick_size - 1))))) {
        ivec3 centre = brick_slot_origin(e) + 1 + local;
        lo = vec4(3.0e38);
        hi = vec4(-3.0e38);
        for (int k = 0; k < 27; ++k) {
            vec4 d = texelFetch(brick_atlas, centre + ivec3(k % 3, (k / 3) % 3, k / 9) - 1, 0);
            lo = min(lo, d);
            hi = max(hi, d);
        }
        return;
    }
#endif
    lo = hi = bricked_voxel(v);
}
#endif
