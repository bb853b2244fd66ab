// The sun's optical depth baked on a grid sheared along the sun's direction
// (light_transmittance.comp), read with hardware trilinear filtering and turned into
// transmittance here. The raymarcher reads it at every step; with WALK_SUN_GRID the bake's walks
// read it at their scattering events instead of tracing a ratio-tracked shadow ray (a bias of the
// grid's resolution and quadrature, measured by the benchmark's bake mode).
//
// The grid's layout (app/rendering/grids/light_transmittance.py, twin app/twins/light_grid.py): `axis` a is
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

uniform float light_grid_texel;        // world length of the grid's largest texel side
uniform float light_grid_march_step;   // the bake's quadrature step (world units)

// The sun's optical depth at x. Within one texel of where the sun's ray from x leaves the box, the
// grid has no texel on the sun's side to interpolate from (along its axis the first texel centre is
// half a texel inside; across it, the neighbouring column lies outside the box with depth 0), and
// the lit skin of a dense medium, thinner than a texel, took a depth the skin's points do not have:
// on a fully opaque box the skin's whole single scattering went dark (the raymarcher's image 85%
// too dark, bench/h100-bias). There the depth is marched to the box instead (the bake's midpoint
// quadrature, at most 8 points: exact where sigma_t is constant); elsewhere it is the grid's.
// (A point whose ray towards the sun does not cross the box, such as one on its sun-side face,
// has depth 0.) LIGHT_GRID_FACE_MARCH 0 (the bake's walks, whose grid sun is corrected without bias
// by shadow rays: lib/integrator.glsl) reads the grid alone: on llvmpipe's coarse grids the march
// covered much of the volume and made a walk's event 2.5x dearer.
#ifndef LIGHT_GRID_FACE_MARCH
#define LIGHT_GRID_FACE_MARCH 1
#endif
float light_grid_optical_depth(vec3 x)
{
#if LIGHT_GRID_FACE_MARCH
    float t0, t1;
    if (!box_intersect(x, sun_direction, t0, t1))
        return 0.0;   // on the box's sun side, leaving it (or outside, not shadowed by it)
    if (t1 < light_grid_texel) {
        int n = clamp(int(ceil((t1 - t0) / light_grid_march_step)), 1, 8);
        float dt = (t1 - t0) / float(n);
        float tau = 0.0;
        for (int i = 0; i < n; ++i)
            tau += sigma_t_at(x + (t0 + (float(i) + 0.5) * dt) * sun_direction) * dt;
        return tau;
    }
#endif
    return texture(light_transmittance, light_grid_coordinates(x)).r;
}

float light_grid_transmittance(vec3 x)
{
    return exp(-light_grid_optical_depth(x));
}
