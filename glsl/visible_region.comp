// The smallest box outside which sigma_t is 0 everywhere, where the probe grid goes (NumPy twin:
// app/twins/visible_region.py, which derives the test). One invocation per cell between two layers
// of voxel centres, with the edge voxel repeated once on each side ((n + 1) cells per axis): the
// cell is visible when the piecewise-linear opacity is > 0 anywhere in [lo, hi] of its 8 voxels.
// Each workgroup reduces its first and last visible cell per axis in shared memory and adds them
// to the global ones with one atomic each.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 4) in;

uniform sampler3D volume_density;        // as lib/medium.glsl: normalised density, texelFetch here
uniform sampler2D transfer_function;     // N x 1 RGBA32F
uniform int transfer_size;               // N
uniform isampler2D positive_node_counts; // (N + 1) x 1: nodes before k with opacity > 0
uniform ivec3 dims;                      // voxels per axis

layout(std430, binding = 0) buffer VisibleCells {
    uint first_cell[3];                  // x, y, z; start at 0xffffffff
    uint last_cell[3];                   // start at 0
};

shared uint group_first[3];
shared uint group_last[3];

bool positive_node(int k)
{
    return texelFetch(transfer_function, ivec2(k, 0), 0).a > 0.0;
}

// t = density * (N - 1) strictly inside a segment whose end nodes are not both transparent.
bool inside_positive_segment(float t)
{
    float node = floor(t);
    if (t == node)
        return false;
    int k = int(node);
    return positive_node(k) || positive_node(min(k + 1, transfer_size - 1));
}

bool opacity_positive_between(float lo, float hi)
{
    float last_node = float(transfer_size - 1);
    float t_lo = clamp(lo, 0.0, 1.0) * last_node;
    float t_hi = clamp(hi, 0.0, 1.0) * last_node;
    int first = int(ceil(t_lo)), last = int(floor(t_hi));
    if (first <= last) {
        int before_first = texelFetch(positive_node_counts, ivec2(min(first, transfer_size), 0), 0).r;
        int through_last = texelFetch(positive_node_counts, ivec2(min(last + 1, transfer_size), 0), 0).r;
        if (through_last > before_first)
            return true;
    }
    return inside_positive_segment(t_lo) || inside_positive_segment(t_hi);
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
    if (all(lessThanEqual(cell, dims))) {
        ivec3 v0 = clamp(cell - 1, ivec3(0), dims - 1), v1 = min(cell, dims - 1);
        float lo = 1.0, hi = 0.0;
        for (int k = 0; k < 8; ++k) {
            ivec3 v = ivec3((k & 1) != 0 ? v1.x : v0.x, (k & 2) != 0 ? v1.y : v0.y,
                            (k & 4) != 0 ? v1.z : v0.z);
            float d = texelFetch(volume_density, v, 0).r;
            lo = min(lo, d);
            hi = max(hi, d);
        }
        if (opacity_positive_between(lo, hi)) {
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
