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

// x[a] at the centre of texel k along the axis.
float column_centre(int k, int a)
{
    return ((2.0 * (float(k) + 0.5)) / float(grid[a]) - 1.0) * box_half_extent[a];
}

void main()
{
    int a = light_grid_axis;
    int b = a == 0 ? 1 : 0;
    int c = a == 2 ? 1 : 2;
    ivec2 ray = ivec2(gl_GlobalInvocationID.xy) + ivec2(0, first_layer);
    if (ray.x >= grid[b] || ray.y >= grid[c])
        return;
    // The ray's sheared coordinates: the world point at x[a] = s is q + shear * s.
    vec3 q = vec3(0.0);
    q[b] = ((2.0 * (float(ray.x) + 0.5)) / float(grid[b]) - 1.0) * light_grid_half_extent[b];
    q[c] = ((2.0 * (float(ray.y) + 0.5)) / float(grid[c]) - 1.0) * light_grid_half_extent[c];
    // Where the ray is inside the box, as an interval of s.
    float h = box_half_extent[a];
    float lo = -h, hi = h;
    for (int i = 1; i <= 2; ++i) {
        int j = (a + i) % 3;
        float k = light_grid_shear[j];
        float e = box_half_extent[j];
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
    float s_from = toward_sun * h;
    ivec3 texel;
    texel[b] = ray.x;
    texel[c] = ray.y;
    for (int n = 0; n < grid[a]; ++n) {
        int k = toward_sun > 0.0 ? grid[a] - 1 - n : n;
        float s_to = column_centre(k, a);
        float s0 = max(min(s_from, s_to), lo), s1 = min(max(s_from, s_to), hi);
        if (s1 > s0 && tau < 104.0) {
            int m = max(1, int(ceil((s1 - s0) * length_per_s / march_step)));
            float ds = (s1 - s0) / float(m);
            for (int i = 0; i < m; ++i) {
                float s = s0 + (float(i) + 0.5) * ds;
                vec3 x = q + light_grid_shear * s;
                x[a] = s;
                tau += sigma_t_at(x) * ds * length_per_s;
            }
        }
        texel[a] = k;
        imageStore(transmittance_image, texel, vec4(tau));
        s_from = s_to;
    }
}
