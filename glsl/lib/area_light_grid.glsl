// Direct single scattering from the area lights (lib/area_lights.glsl) for the renderers that read
// no shadow rays: the raymarcher and probes-only (AREA_LIGHTS only). NumPy twin:
// app/twins/area_light_grid.py.
//
// The light light i sheds on a point x, integrated over the directions of the light, is taken as
//   L_i * Omega_i(x) * k(w_i) * exp(-tau_i(x))
// with Omega_i the light's exact solid angle from x (a sphere's cone 2 pi (1 - cos theta_max); a
// rectangle's planar quadrilateral, two triangles by Van Oosterom and Strackee's formula, 0 from
// behind its emitting face), w_i the direction to its centre, k the phase function (or a
// surface's BRDF times the cosine) towards w_i, and tau_i the optical depth from x towards the
// centre, baked on a grid (area_light_transmittance.comp). Exact for a small light; for a large
// near one its bias is the variation of k and of the transmittance over the light's directions
// (docs/design.md, Area lights, bounds it). Another light in front of light i is not seen.
//
// The grid: one block of texels per light over the box the sun's light grid covers (the volume
// box, or a crop's kept box), centred at area_light_grid_centre, texel centres at
// ((2 (k + 0.5)) / size - 1) * half extent per axis; the blocks are stacked along z in one 3D
// texture (light i's texel k at z = i size.z + k) read with trilinear filtering of optical depth,
// z clamped to the block's own texel centres (clamp-to-edge per block).
uniform sampler3D area_light_transmittance;
uniform ivec3 area_light_grid_size;          // texels per axis of one light's block
uniform vec3 area_light_grid_centre;
uniform vec3 area_light_grid_half_extent;
uniform float area_light_grid_texel;         // world length of the largest texel side
uniform float area_light_grid_march_step;    // the bake's quadrature step (world units)

const float AREA_LIGHT_TAU_OPAQUE = 104.0;   // exp(-tau) is 0 in float32 from here on

// The solid angle of the triangle a, b, c seen from the origin (Van Oosterom and Strackee 1983).
float triangle_solid_angle(vec3 a, vec3 b, vec3 c)
{
    float la = length(a), lb = length(b), lc = length(c);
    float numerator = abs(dot(a, cross(b, c)));
    float denominator = la * lb * lc + dot(a, b) * lc + dot(a, c) * lb + dot(b, c) * la;
    return 2.0 * atan(numerator, denominator);
}

// The exact solid angle light i fills seen from x (outside the light): 0 behind a rectangle.
float area_light_solid_angle(int i, vec3 x)
{
    if (area_light_shape[i] == AREA_LIGHT_SPHERE) {
        vec3 axis;
        float cos_max;
        return 2.0 * PI * area_light_cone(i, x, axis, cos_max);
    }
    vec3 u = area_light_u[i], v = area_light_v[i];
    vec3 c = area_light_position[i] - x;
    if (dot(c, cross(u, v)) >= 0.0)
        return 0.0;                                  // x behind the emitting face
    vec3 p0 = c - u - v, p1 = c + u - v, p2 = c + u + v, p3 = c - u + v;
    return triangle_solid_angle(p0, p1, p2) + triangle_solid_angle(p0, p2, p3);
}

// The midpoint quadrature of sigma_t along x + t w over [0, t_end] in n points.
float area_light_march(vec3 x, vec3 w, float t_end, int n)
{
    float dt = t_end / float(n);
    float tau = 0.0;
    for (int k = 0; k < n && tau < AREA_LIGHT_TAU_OPAQUE; ++k)
        tau += sigma_t_at(x + (float(k) + 0.5) * dt * w) * dt;
    return tau;
}

#if !defined(AREA_LIGHT_GRID_BAKE)
// The optical depth from x towards light i's centre: the grid's, but within one texel of where
// that ray leaves the box (no texel on the light's side to interpolate from: a dense skin would
// take a depth its points do not have, as the sun's grid once did) the march to the box (at most
// 8 points of about the bake's step), as lib/light_grid.glsl does for the sun.
float area_light_optical_depth(int i, vec3 x)
{
    vec3 w = normalize(area_light_position[i] - x);
    float t0, t1;
    if (!box_intersect(x, w, t0, t1))
        return 0.0;
    if (t1 < area_light_grid_texel)
        return area_light_march(x + t0 * w, w, t1 - t0,
                                clamp(int(ceil((t1 - t0) / area_light_grid_march_step)), 1, 8));
    vec3 uvw = (x - area_light_grid_centre) / (2.0 * area_light_grid_half_extent) + 0.5;
    float depth = float(area_light_grid_size.z);
    uvw.z = (clamp(uvw.z * depth, 0.5, depth - 0.5) + float(i) * depth)
            / (depth * float(area_light_count));
    return texture(area_light_transmittance, uvw).r;
}

// The light at x from every light, per unit of the kernel: L_i Omega_i exp(-tau_i) and the
// direction w_i (unit, towards the centre) for light i.
vec3 area_light_direct(int i, vec3 x, out vec3 w)
{
    w = normalize(area_light_position[i] - x);
    return area_light_radiance[i]
           * (area_light_solid_angle(i, x) * exp(-area_light_optical_depth(i, x)));
}
#endif
