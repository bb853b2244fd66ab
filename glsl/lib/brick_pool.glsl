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
// The checking build (SHADER_CHECKS, lib/checks.glsl) reads brick_of_slot (the brick each slot
// holds, written by the host; 0xffffffff for a free slot) and counts CHECK_SITE_PAGE_MISS where the
// page table sends a brick to a slot holding another brick or none, or to a constant past the
// table of constants.
#include "lib/checks.glsl"
#if !defined(VOLUME_BRICKED)
#define VOLUME_BRICKED 0
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
#if defined(SHADER_CHECKS)
#ifndef BRICK_SLOTS_BINDING
#define BRICK_SLOTS_BINDING 10
#endif
uniform int brick_constant_count;     // constants in brick_constants
layout(std430, binding = BRICK_SLOTS_BINDING) readonly buffer BrickSlots {
    uint brick_of_slot[];             // the linear brick index (x + bx (y + by z)) a slot holds
};
#endif

// The page table's entry of brick b (the checking build checks it against brick_of_slot).
uint brick_entry(ivec3 b)
{
    uint e = texelFetch(brick_table, b, 0).r;
#if defined(SHADER_CHECKS)
    if ((e & BRICK_CONSTANT) != 0u) {
        CHECK_INDEX(e & ~BRICK_CONSTANT, brick_constant_count, CHECK_SITE_PAGE_MISS);
    } else {
        uint brick = uint(b.x + brick_counts.x * (b.y + brick_counts.y * b.z));
        uint slots = uint(brick_slots.x * brick_slots.y * brick_slots.z);
        CHECK_TRUE(e < slots && brick_of_slot[min(e, slots - 1u)] == brick, CHECK_SITE_PAGE_MISS);
    }
#endif
    return e;
}

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

// texture(volume, uvw) of the whole volume (cell-centred, trilinear, clamped to the edge voxel).
vec4 bricked_sample(vec3 uvw)
{
    // t in voxels from the volume's low face; clamping to the box changes no value (beyond the
    // outermost voxel centres the filter returns the edge voxel) and keeps every point inside a
    // brick's apron.
    vec3 dims = vec3(brick_volume_dims);
    vec3 t = clamp(uvw * dims, vec3(0.0), dims);
    ivec3 b = clamp(ivec3(floor(t / float(brick_size))), ivec3(0), brick_counts - 1);
    uint e = brick_entry(b);
    if ((e & BRICK_CONSTANT) != 0u)
        return brick_constant(e);
    // the voxel coordinate s = t - 0.5 in the brick (its voxels at 0 .. B - 1), one texel past
    // the apron, and half a texel to the texel's centre: the atlas coordinate of s.
    vec3 texel = vec3(brick_slot_origin(e)) + 1.5 + (t - 0.5 - vec3(b * brick_size));
    return texture(brick_atlas, texel / vec3(textureSize(brick_atlas, 0)));
}

// texelFetch(volume, v, 0) of the whole volume (v inside it).
vec4 bricked_voxel(ivec3 v)
{
    ivec3 b = clamp(v / brick_size, ivec3(0), brick_counts - 1);
    uint e = brick_entry(b);
    if ((e & BRICK_CONSTANT) != 0u)
        return brick_constant(e);
    return texelFetch(brick_atlas, brick_slot_origin(e) + 1 + v - b * brick_size, 0);
}
#endif
