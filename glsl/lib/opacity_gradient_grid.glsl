// The opacity gradient the raymarcher's hybrid branch reads (lib/raymarch.glsl; the raymarcher
// alone: the path tracer, the probes' walks and `guided` call opacity_gradient, exact, since the
// path tracer is the unbiased reference). NumPy twin: app/twins/opacity_gradient_grid.py.
//
// OPACITY_GRADIENT_GRID (app/rendering/grids/opacity_gradient_grid.py): grad A baked at every voxel's
// centre by glsl/opacity_gradient_bake.comp, with lib/hybrid_scattering.glsl's opacity_gradient
// itself (so exact at each texel centre, crop, clip plane and channels included), and read here
// in one fetch with hardware trilinear filtering, where opacity_gradient takes six classified_at
// lookups (a density fetch, two table reads and the crop test each): on an H200 at 1080p those
// were 1.1 ms of the foot's 3.9 ms hybrid frame, one texture read almost nothing
// (bench/h200-hybrid-cost). Between texel centres it is the trilinear blend of the centres'
// gradients, not the central difference at x: a bias, measured against the exact gradient and
// the path tracer (docs/design.md, Surfaces inside the volume).
//
// Without it the raymarcher takes the exact gradient: a bricked volume (VOLUME_BRICKED: too large
// for one texture, and the grid's 8 bytes a voxel are 4 or 2 times its 16- or 32-bit texels), a
// grid over the memory budget (opacity_gradient_grid.py MAX_BYTES), or
// LabOptions.opacity_gradient_grid False. No second approximation stands in for the grid there.
#if defined(OPACITY_GRADIENT_GRID)
#if VOLUME_BRICKED
#error "the opacity-gradient grid is for a volume in one texture (opacity_gradient_grid.py)"
#endif
// RGBA16F, texel (i, j, k) grad A at the centre of voxel (i, j, k) (a unused), linear, clamped
// to the edge: it covers the volume box as the density texture does.
uniform sampler3D opacity_gradient_texture;

// grad A at x, trilinear between the voxel centres' gradients (world units).
vec3 opacity_gradient_grid(vec3 x)
{
    return texture(opacity_gradient_texture, x / (2.0 * box_half_extent) + 0.5).rgb;
}
#endif

// The gradient the raymarcher shades a sample with: the grid's where there is one, else exact.
vec3 raymarch_opacity_gradient(vec3 x)
{
#if defined(OPACITY_GRADIENT_GRID)
    return opacity_gradient_grid(x);
#else
    return opacity_gradient(x);
#endif
}
