// Bakes the sun's optical depth on the sheared light grid (lib/light_grid.glsl) for the raymarcher
// and the bake's walks. Optical depth, not transmittance: it varies slowly (about linearly along
// the sun's direction), so trilinear filtering of it is nearly exact where filtering exp(-tau)
// would overestimate the light (exp is convex).
//
// One invocation per sun ray (a texel column along the grid's axis a): it starts on the box's
// sun side with tau = 0 and walks away from the sun through the column's texel centres, adding
// the midpoint quadrature of sigma_t over each segment between them (steps of at most
// march_step, only where the ray is inside the box) and storing the running sum. Every texel
// costs one segment, where a march from each texel to the boundary costs the whole way.
// Once past tau = 104 (exp(-tau) is 0 in float32) it stops adding.
//
// Rays are numbered along the two other axes b < c (LightGridLayout.ray_axes), b across a work
// group's 32 consecutive invocations: whenever x is not the march axis, neighbouring invocations
// write neighbouring texels of one row of the texture.
//
// The texels hold min(tau, 104): past it the transmittance is 0 either way, and the cap makes a
// column's values independent of where the march stopped adding.
//
// Segments (LIGHT_GRID_SEGMENTS 1, gl_GlobalInvocationID.z the segment): a column is one chain of
// dependent fetches as long as the grid is deep, and a small grid has too few columns to fill a
// large GPU, which then waits for the chain (on an H100, 0.081 to 0.091 ms for the 8^3 probe
// grids' light grids of 29 to 38 thousand columns, 0.064 to 0.072 ms in 7 to 9 segments; when
// to cut: light_transmittance.py). So each column is cut into `segments` runs of texels, one
// invocation each, in two dispatches: segment_pass 0 sums each run's optical depth into
// segment_tau; segment_pass 1 starts each run from the sum of the runs before it and stores its
// texels. The same quadrature points as one march, summed in another order (float rounding).
// LIGHT_GRID_SEGMENTS 0 (or undefined) marches whole columns, with none of this in the code (the
// segmented build's code made whole columns 11 to 16% slower on the H100).
layout(local_size_x = 32, local_size_y = 2) in;
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/light_grid.glsl"

#ifndef LIGHT_GRID_FORMAT
#define LIGHT_GRID_FORMAT r32f
#endif
layout(LIGHT_GRID_FORMAT, binding = 0) uniform writeonly image3D transmittance_image;
uniform ivec3 grid;
uniform int first_layer;   // a slab of rays along axis c per dispatch (bake_layers)
uniform float march_step;  // world units between quadrature points at most
// The box the grid covers (the volume box, or a crop's kept box), centred at light_grid_centre:
// rays are marched inside it alone (beyond it sigma_t is 0).
uniform vec3 light_box_half_extent;
#if LIGHT_GRID_SEGMENTS
uniform int segments;      // runs of texels per column
uniform int segment_pass;  // 0 sums each run, 1 stores the texels
layout(std430, binding = 0) buffer SegmentDepths { float segment_tau[]; };  // [ray][segment]
#endif

const float TAU_OPAQUE = 104.0;   // exp(-tau) is 0 in float32 from here on

// x[a] at the centre of texel k along the axis.
float column_centre(int k, int a)
{
    return ((2.0 * (float(k) + 0.5)) / float(grid[a]) - 1.0) * light_box_half_extent[a];
}

void main()
{
    int a = light_grid_axis;
    int b = a == 0 ? 1 : 0;
    int c = a == 2 ? 1 : 2;
    ivec2 ray = ivec2(gl_GlobalInvocationID.xy) + ivec2(0, first_layer);
#if LIGHT_GRID_SEGMENTS
    int segment = int(gl_GlobalInvocationID.z);
    if (ray.x >= grid[b] || ray.y >= grid[c] || segment >= segments)
        return;
#else
    if (ray.x >= grid[b] || ray.y >= grid[c])
        return;
#endif
    // The ray's sheared coordinates: the world point at x[a] = s is q + shear * s.
    vec3 q = vec3(0.0);
    q[b] = ((2.0 * (float(ray.x) + 0.5)) / float(grid[b]) - 1.0) * light_grid_half_extent[b];
    q[c] = ((2.0 * (float(ray.y) + 0.5)) / float(grid[c]) - 1.0) * light_grid_half_extent[c];
    // Where the ray is inside the box, as an interval of s.
    float h = light_box_half_extent[a];
    float lo = -h, hi = h;
    for (int i = 1; i <= 2; ++i) {
        int j = (a + i) % 3;
        float k = light_grid_shear[j];
        float e = light_box_half_extent[j];
        if (k == 0.0) {
            if (abs(q[j]) > e) { lo = 1.0; hi = -1.0; }
        } else {
            float s0 = (-e - q[j]) / k, s1 = (e - q[j]) / k;
            lo = max(lo, min(s0, s1));
            hi = min(hi, max(s0, s1));
        }
    }
    float toward_sun = sun_direction[a] > 0.0 ? 1.0 : -1.0;
    float length_per_s = 1.0 / abs(sun_direction[a]);   // world length per unit of s
    float tau = 0.0;
    // This invocation's texels, in march order n (n = 0 nearest the sun): [n_begin, n_end).
#if LIGHT_GRID_SEGMENTS
    int run = (grid[a] + segments - 1) / segments;
    int n_begin = segment * run;
    int n_end = min(grid[a], n_begin + run);
    bool store = segment_pass == 1;
    uint ray_index = uint(ray.y * grid[b] + ray.x);
    if (store)
        for (int j = 0; j < segment; ++j)
            CHECK_INDEX(ray_index * uint(segments) + uint(j), segment_tau.length(),
                        CHECK_SITE_SEGMENT_INDEX);
    if (store)
        for (int j = 0; j < segment; ++j)
            tau += segment_tau[ray_index * uint(segments) + uint(j)];
    // Texel n covers s from the centre of texel n - 1 (the box's sun side for n = 0) to its own.
    int k_from = toward_sun > 0.0 ? grid[a] - n_begin : n_begin - 1;
    float s_from = n_begin == 0 ? toward_sun * h : column_centre(k_from, a);
#else
    const int n_begin = 0;
    int n_end = grid[a];
    const bool store = true;
    float s_from = toward_sun * h;
#endif
    ivec3 texel;
    texel[b] = ray.x;
    texel[c] = ray.y;
    for (int n = n_begin; n < n_end; ++n) {
        int k = toward_sun > 0.0 ? grid[a] - 1 - n : n;
        float s_to = column_centre(k, a);
        float s0 = max(min(s_from, s_to), lo), s1 = min(max(s_from, s_to), hi);
        if (s1 > s0 && tau < TAU_OPAQUE) {
            int m = max(1, int(ceil((s1 - s0) * length_per_s / march_step)));
            float ds = (s1 - s0) / float(m);
            for (int i = 0; i < m; ++i) {
                float s = s0 + (float(i) + 0.5) * ds;
                vec3 x = q + light_grid_shear * s;
                x[a] = s;
                tau += sigma_t_at(light_grid_centre + x) * ds * length_per_s;
            }
        }
        if (store) {
            texel[a] = k;
            CHECK_TEXEL(texel, imageSize(transmittance_image), CHECK_SITE_IMAGE_TEXEL);
            imageStore(transmittance_image, texel, vec4(min(tau, TAU_OPAQUE)));
        }
        s_from = s_to;
    }
#if LIGHT_GRID_SEGMENTS
    if (!store)
        CHECK_INDEX(ray_index * uint(segments) + uint(segment), segment_tau.length(),
                    CHECK_SITE_SEGMENT_INDEX);
    if (!store)
        segment_tau[ray_index * uint(segments) + uint(segment)] = tau;
#endif
}
