// Bakes the raymarcher's opacity-gradient grid (lib/opacity_gradient_grid.glsl; NumPy twin
// app/twins/opacity_gradient_grid.py opacity_gradient_bake): one invocation per voxel, grad A at
// the voxel's centre by lib/hybrid_scattering.glsl's opacity_gradient, the same six classified_at
// lookups the path tracer makes, so the crop, the clip plane and several channels' mixture follow
// (and the grid is exact at its texel centres). Rebuilt when the volume, the transfer functions,
// the channels, the crop or the clip plane change (app/rendering/grids/opacity_gradient_grid.py).
//
// Stored as RGBA16F (image formats have no rgb16f; a is 0). 16 bits are enough: a half float
// holds each component to 2^-11 relative (4.9e-4) up to 65504. |grad A| stays below about 4100 in
// a volume one texture holds (4 channels' opacity over one voxel of a 2048-voxel side); a voxel
// thinner than 1/16000 of the box's longest side could pass 65504, and is clamped there rather
// than made infinite (a NaN normal). The rounding moves P = 1 - exp(-k |g|) by at most
// k |g| exp(-k |g|) 4.9e-4 <= 1.8e-4 and the normal by about 5e-4 rad; gradients below the
// smallest normal half (6.1e-5) keep 6e-8 absolute, moving P by k 6e-8 (6e-4 at the largest k a
// scene takes, 10^4). Both far below the grid's interpolation bias (docs/design.md), in half the
// memory of RGBA32F (8 bytes a voxel against 16).
layout(local_size_x = 4, local_size_y = 4, local_size_z = 4) in;
#include "lib/medium.glsl"
// (lib/phase.glsl: PI and orthonormal_basis, which the BRDF beside opacity_gradient uses)
#include "lib/phase.glsl"
#include "lib/hybrid_scattering.glsl"

layout(rgba16f, binding = 0) uniform writeonly image3D opacity_gradient_image;
uniform ivec3 grid;   // the volume's voxels along x, y, z (one texel each)

void main()
{
    ivec3 v = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(v, grid)))
        return;
    // the voxel's centre: where the density texture's texel v sits, and the grid's
    vec3 x = (2.0 * (vec3(v) + 0.5) / vec3(grid) - 1.0) * box_half_extent;
    CHECK_TEXEL(v, imageSize(opacity_gradient_image), CHECK_SITE_IMAGE_TEXEL);
    const float HALF_MAX = 65504.0;
    imageStore(opacity_gradient_image, v,
               vec4(clamp(opacity_gradient(x), vec3(-HALF_MAX), vec3(HALF_MAX)), 0.0));
}
