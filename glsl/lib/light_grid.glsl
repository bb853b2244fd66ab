// The sun's optical depth baked on a grid sheared along the sun's direction
// (light_transmittance.comp), read with hardware trilinear filtering and turned into
// transmittance here. The raymarcher reads it at every step; with WALK_SUN_GRID the bake's walks
// read it at their scattering events instead of tracing a ratio-tracked shadow ray (a bias of the
// grid's resolution and quadrature, measured by the benchmark's bake mode).
//
// The grid's layout (app/render/light_transmittance.py, twin app/twins/light_grid.py): `axis` a is
// the sun direction's largest component; a world point x has sheared coordinates
// q = x - shear * x[a], with shear = sun_direction / sun_direction[a] and shear[a] = 0, so every
// point of one sun ray has the same q along the two other axes, and q[a] = x[a]. Texel centres
// sit at q = ((2 (i + 0.5)) / size - 1) * light_grid_half_extent. With the sun along an axis the
// shear is 0 and the grid is the box's own. (x here is relative to light_grid_centre.)
uniform sampler3D light_transmittance;
uniform int light_grid_axis;             // a: 0 x, 1 y, 2 z
uniform vec3 light_grid_axis_mask;       // the unit vector along a
uniform vec3 light_grid_shear;           // sun_direction / sun_direction[a], component a zero
uniform vec3 light_grid_half_extent;     // half the range of q per axis (box_half_extent along a)
// The box the grid covers is centred here (the volume box's centre, the origin, unless a crop
// or clip plane fitted the grid to the kept box); q is relative to it.
uniform vec3 light_grid_centre;

// Texture coordinates of world point x. (x[a] as a dot product: indexing a vector by a uniform
// made the bake's walks, which read this at every scattering event, 2x slower on an H100.)
vec3 light_grid_coordinates(vec3 x)
{
    x -= light_grid_centre;
    vec3 q = x - light_grid_shear * dot(x, light_grid_axis_mask);
    return q / (2.0 * light_grid_half_extent) + 0.5;
}

float light_grid_transmittance(vec3 x)
{
    return exp(-texture(light_transmittance, light_grid_coordinates(x)).r);
}
