// The sun's optical depth baked on a grid over the box (light_transmittance.comp: deterministic
// quadrature from each texel centre to the boundary), read with hardware trilinear filtering and
// turned into transmittance here. The
// raymarcher reads it at every step; with WALK_SUN_GRID the bake's walks read it at their
// scattering events instead of tracing a ratio-tracked shadow ray (a bias of the grid's
// resolution and quadrature, measured by the benchmark's bake mode).
uniform sampler3D light_transmittance;

float light_grid_transmittance(vec3 x)
{
    return exp(-texture(light_transmittance, x / (2.0 * box_half_extent) + 0.5).r);
}
