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
// The optical depth from x towards light i's centre: the first AREA_LIGHT_NEAR_TEXELS texels of
// the way marched (at most AREA_LIGHT_NEAR_POINTS midpoints of about the bake's step), the rest
// read from the grid at the point that far along the ray, where the texels it interpolates all
// lie beyond x (the trilinear stencil reaches sqrt(3) texels from its centre). So a point on the
// lit side of a dense surface thinner than a texel (bone under a light, a shell's skin) takes
// its own depth, not the blend of texels behind the surface, which darkened such skins as the
// sun's grid once did (bench/h100-bias); where the box ends within that reach (the box's side
// towards the light) the march goes to the box and no texel is read.
// (AREA_LIGHT_NEAR_POINTS 0, a lab build, LabOptions.area_light_near_points: the grid's read at
// x alone, no march.)
#ifndef AREA_LIGHT_NEAR_POINTS
#define AREA_LIGHT_NEAR_POINTS 4
#endif
const float AREA_LIGHT_NEAR_TEXELS = 2.0;

// Light i's block of the grid read at x.
float area_light_grid_read(int i, vec3 x)
{
    vec3 uvw = (x - area_light_grid_centre) / (2.0 * area_light_grid_half_extent) + 0.5;
    float depth = float(area_light_grid_size.z);
    uvw.z = (clamp(uvw.z * depth, 0.5, depth - 0.5) + float(i) * depth)
            / (depth * float(area_light_count));
    return texture(area_light_transmittance, uvw).r;
}

float area_light_optical_depth(int i, vec3 x)
{
    vec3 w = normalize(area_light_position[i] - x);
    float t0, t1;
    if (!box_intersect(x, w, t0, t1))
        return 0.0;
#if AREA_LIGHT_NEAR_POINTS > 0
    float t_near = min(t1, min(AREA_LIGHT_NEAR_TEXELS * area_light_grid_texel,
                               float(AREA_LIGHT_NEAR_POINTS) * area_light_grid_march_step));
    if (!(t_near > t0))
        return 0.0;
    float tau = area_light_march(x + t0 * w, w, t_near - t0,
                                 clamp(int(ceil((t_near - t0) / area_light_grid_march_step)), 1,
                                       AREA_LIGHT_NEAR_POINTS));
    if (t1 <= t_near)
        return tau;
    return tau + area_light_grid_read(i, x + t_near * w);
#else
    return area_light_grid_read(i, x);
#endif
}

// Light i's direct light at x per unit of the kernel, L_i Omega_i exp(-tau_i), the direction w_i
// (unit, towards the centre) and the solid angle Omega_i.
vec3 area_light_direct(int i, vec3 x, out vec3 w, out float solid_angle)
{
    w = normalize(area_light_position[i] - x);
    solid_angle = area_light_solid_angle(i, x);
    return area_light_radiance[i] * (solid_angle * exp(-area_light_optical_depth(i, x)));
}
#endif

// The anisotropy with which the phase function towards a light's centre stands in for its mean
// over the light's directions: Henyey-Greenstein's g^l bands times the uniform cap's own, matched
// at band 1, (1 + cos theta) / 2 = 1 - Omega / (4 pi) for a cap of solid angle Omega (a
// rectangle taken as the cap of its solid angle). g itself for a small light; the mean's first
// moment exact for a sphere (docs/design.md, Area lights, measures what the higher bands leave).
float area_light_anisotropy(float g, float solid_angle)
{
    return g * (1.0 - solid_angle / (4.0 * PI));
}
