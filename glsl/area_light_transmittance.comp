// Bakes the area lights' optical-depth grid (lib/area_light_grid.glsl): one invocation per texel
// of the stacked blocks (light i's texel k at z = i size.z + k), marching sigma_t from the texel's
// centre towards the light's centre to where that ray leaves the box (the light lies beyond it),
// midpoint quadrature in steps of at most march_step, no more added once past tau = 104 and the
// texel capped there. Every texel marches its own ray (the rays of a light at a finite distance
// do not share columns as the sun's do), so a texel costs its distance to the box's far side in
// steps (empty space skipped by the majorant grid, as the raymarcher does). z layers first_layer .. first_layer + gl_NumWorkGroups.z * 4 - 1 per dispatch (sliced).
// NumPy twin: app/twins/area_light_grid.py bake.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 4) in;
#define AREA_LIGHT_GRID_BAKE
#include "lib/medium.glsl"
#include "lib/phase.glsl"
#include "lib/area_lights.glsl"
#include "lib/area_light_grid.glsl"
#include "lib/cell_walk.glsl"

layout(r16f, binding = 0) uniform writeonly image3D optical_depth_image;
uniform int first_layer;   // of the stacked z layers

// The midpoint quadrature of sigma_t along x + t w over [0, t_end] in n points, as
// area_light_march, with empty space skipped exactly as the raymarcher skips it: at an empty
// point whose macrocell the majorant grid bounds by 0, every point up to the cell's exit is empty
// too, and the march goes on from the last of them (rounding may look at one more point inside the
// cell, never skip one beyond it). The same points add the same sum.
float march_skipping(vec3 x, vec3 w, float t_end, int n)
{
    float dt = t_end / float(n);
    float tau = 0.0;
    for (int k = 0; k < n && tau < AREA_LIGHT_TAU_OPAQUE; ++k) {
        float t = (float(k) + 0.5) * dt;
        float sigma_t = sigma_t_at(x + t * w);
        if (sigma_t <= 0.0) {
#if !defined(GLOBAL_MAJORANT)
            CellWalk cells;
            if (use_majorant_grid != 0 && cell_walk_begin(x, w, t, cells)
                && cell_majorant(cells) <= 0.0)
                k = max(k, int(floor(cell_walk_exit(cells) / dt - 0.5)) - 1);
#endif
            continue;
        }
        tau += sigma_t * dt;
    }
    return tau;
}

void main()
{
    ivec3 texel = ivec3(gl_GlobalInvocationID) + ivec3(0, 0, first_layer);
    ivec3 size = area_light_grid_size;
    if (texel.x >= size.x || texel.y >= size.y || texel.z >= size.z * area_light_count)
        return;
    int light = texel.z / size.z;
    ivec3 k = ivec3(texel.xy, texel.z - light * size.z);
    vec3 x = area_light_grid_centre
             + ((2.0 * (vec3(k) + 0.5)) / vec3(size) - 1.0) * area_light_grid_half_extent;
    vec3 w = normalize(area_light_position[light] - x);
    float t0, t1;
    float tau = 0.0;
    if (box_intersect(x, w, t0, t1))
        tau = march_skipping(x + t0 * w, w, t1 - t0,
                             max(1, int(ceil((t1 - t0) / area_light_grid_march_step))));
    CHECK_TEXEL(texel, imageSize(optical_depth_image), CHECK_SITE_IMAGE_TEXEL);
    imageStore(optical_depth_image, texel, vec4(min(tau, AREA_LIGHT_TAU_OPAQUE)));
}
