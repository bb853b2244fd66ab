// Bakes the sun's transmittance on a grid over the box (texel centres), for the raymarcher.
layout(local_size_x = 4, local_size_y = 4, local_size_z = 4) in;
#include "lib/medium.glsl"
#include "lib/lights.glsl"
#include "lib/shadow_march.glsl"

layout(r32f, binding = 0) uniform writeonly image3D transmittance_image;
uniform ivec3 grid;

void main()
{
    ivec3 texel = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(texel, grid)))
        return;
    vec3 x = ((2.0 * (vec3(texel) + 0.5)) / vec3(grid) - 1.0) * box_half_extent;
    imageStore(transmittance_image, texel, vec4(sun_transmittance_march(x)));
}
