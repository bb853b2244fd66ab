// The smallest box outside which sigma_t is 0 everywhere, where the probe grid goes (NumPy twin:
// app/twins/visible_region.py, which derives the test). One invocation per cell between two layers
// of voxel centres, with the edge voxel repeated once on each side ((n + 1) cells per axis): the
// cell is visible when the piecewise-linear opacity is > 0 anywhere in [lo, hi] of its 8 voxels.
// Each workgroup reduces its first and last visible cell per axis in shared memory and adds them
// to the global ones with one atomic each.
// With a crop (lib/clip_region.glsl) the pass runs over the kept voxels alone, the first and last
// of them repeated as the volume's edge voxels are (the density of a kept point never reads a
// voxel cut away), and the outer cells reach the kept box's faces; with a clip plane, a cell
// wholly on its far side is not visible. Without either, voxel_first is 0 and voxel_count dims.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 4) in;

// Several channels (MEDIUM_CHANNELS > 1): a cell is visible where any channel switched on is.
#if !defined(MEDIUM_CHANNELS)
#define MEDIUM_CHANNELS 1
#endif
uniform sampler3D volume_density;        // as lib/medium.glsl: normalised density, texelFetch here
uniform sampler2D transfer_function;     // N x C RGBA32F (a row a channel)
uniform int transfer_size;               // N
uniform isampler2D positive_node_counts; // (N + 1) x C: nodes before k with opacity > 0
#if MEDIUM_CHANNELS > 1
uniform ivec4 channel_transfer_size;     // each channel's N
uniform vec4 channel_on;                 // 1 shown, 0 switched off
#define TABLE_SIZE(ch) channel_transfer_size[ch]
#else
#define TABLE_SIZE(ch) transfer_size
#endif
uniform ivec3 dims;                      // voxels per axis
uniform ivec3 voxel_first;               // the kept voxels: first and count per axis
uniform ivec3 voxel_count;
uniform vec3 box_half_extent;            // the volume box, for the cells' world corners
#include "lib/clip_region.glsl"
#include "lib/brick_pool.glsl"

layout(std430, binding = 0) buffer VisibleCells {
    uint first_cell[3];                  // x, y, z; start at 0xffffffff
    uint last_cell[3];                   // start at 0
};

shared uint group_first[3];
shared uint group_last[3];

bool positive_node(int ch, int k)
{
    return texelFetch(transfer_function, ivec2(k, ch), 0).a > 0.0;
}

// t = density * (N - 1) strictly inside a segment whose end nodes are not both transparent.
bool inside_positive_segment(int ch, float t)
{
    float node = floor(t);
    if (t == node)
        return false;
    int k = int(node);
    return positive_node(ch, k) || positive_node(ch, min(k + 1, TABLE_SIZE(ch) - 1));
}

// Channel ch's opacity > 0 somewhere in densities [lo, hi].
bool opacity_positive_between(int ch, float lo, float hi)
{
    int n = TABLE_SIZE(ch);
    float last_node = float(n - 1);
    float t_lo = clamp(lo, 0.0, 1.0) * last_node;
    float t_hi = clamp(hi, 0.0, 1.0) * last_node;
    int first = int(ceil(t_lo)), last = int(floor(t_hi));
    if (first <= last) {
        int before_first = texelFetch(positive_node_counts, ivec2(min(first, n), ch), 0).r;
        int through_last = texelFetch(positive_node_counts, ivec2(min(last + 1, n), ch), 0).r;
        if (through_last > before_first)
            return true;
    }
    return inside_positive_segment(ch, t_lo) || inside_positive_segment(ch, t_hi);
}

// Whether the clip plane leaves nothing of the cell (between voxel centres voxel_first + cell - 1
// and voxel_first + cell, the outer cells reaching the kept box's faces).
bool cell_cut_away(ivec3 cell)
{
    if (clip_region_on == 0)
        return false;
    vec3 lo = ((2.0 * (vec3(voxel_first + cell) - 0.5)) / vec3(dims) - 1.0) * box_half_extent;
    vec3 hi = ((2.0 * (vec3(voxel_first + cell) + 0.5)) / vec3(dims) - 1.0) * box_half_extent;
    lo = mix(lo, kept_box_min, equal(cell, ivec3(0)));
    hi = mix(hi, kept_box_max, equal(cell, voxel_count));
    vec3 slack = box_half_extent / vec3(dims) * (1.0 / 64.0);
    return clip_region_cuts_box(lo - slack, hi + slack);
}

void main()
{
    if (gl_LocalInvocationIndex == 0u) {
        for (int a = 0; a < 3; ++a) {
            group_first[a] = 0xffffffffu;
            group_last[a] = 0u;
        }
    }
    barrier();
    ivec3 cell = ivec3(gl_GlobalInvocationID);
    if (all(lessThanEqual(cell, voxel_count)) && !cell_cut_away(cell)) {
        ivec3 last_voxel = voxel_first + voxel_count - 1;
        ivec3 v0 = clamp(voxel_first + cell - 1, voxel_first, last_voxel);
        ivec3 v1 = min(voxel_first + cell, last_voxel);
        vec4 lo = vec4(1.0), hi = vec4(0.0);
        for (int k = 0; k < 8; ++k) {
            ivec3 v = ivec3((k & 1) != 0 ? v1.x : v0.x, (k & 2) != 0 ? v1.y : v0.y,
                            (k & 4) != 0 ? v1.z : v0.z);
#if VOLUME_BRICKED
            vec4 d_lo, d_hi;
            bricked_voxel_range(v, d_lo, d_hi);
            lo = min(lo, d_lo);
            hi = max(hi, d_hi);
#else
            vec4 d = texelFetch(volume_density, v, 0);
            lo = min(lo, d);
            hi = max(hi, d);
#endif
        }
        bool visible = false;
        for (int ch = 0; ch < MEDIUM_CHANNELS; ++ch) {
#if MEDIUM_CHANNELS > 1
            if (channel_on[ch] == 0.0)
                continue;
#endif
            visible = visible || opacity_positive_between(ch, lo[ch], hi[ch]);
        }
        if (visible) {
            for (int a = 0; a < 3; ++a) {
                atomicMin(group_first[a], uint(cell[a]));
                atomicMax(group_last[a], uint(cell[a]));
            }
        }
    }
    barrier();
    if (gl_LocalInvocationIndex == 0u && group_first[0] != 0xffffffffu) {
        for (int a = 0; a < 3; ++a) {
            atomicMin(first_cell[a], group_first[a]);
            atomicMax(last_cell[a], group_last[a]);
        }
    }
}
