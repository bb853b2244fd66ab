// Bakes the sun's optical depth on a grid over the box (texel centres), for the raymarcher and
// the bake's walks (lib/light_grid.glsl). Optical depth, not transmittance: it varies slowly
// (about linearly along the sun's direction), so trilinear filtering of it is nearly exact where
// filtering exp(-tau) would overestimate the light (exp is convex).
layout(local_size_x = 4, local_size_y = 4, local_size_z = 4) in;
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/shadow_march.glsl"

layout(r32f, binding = 0) uniform writeonly image3D transmittance_image;
uniform ivec3 grid;
uniform int first_layer;   // a slab of z layers per dispatch (LightTransmittance.bake_layers)

void main()
{
    ivec3 texel = ivec3(gl_GlobalInvocationID) + ivec3(0, 0, first_layer);
    if (any(greaterThanEqual(texel, grid)))
        return;
    vec3 x = ((2.0 * (vec3(texel) + 0.5)) / vec3(grid) - 1.0) * box_half_extent;
    imageStore(transmittance_image, texel, vec4(sun_optical_depth_march(x)));
}
