// Area lights (the scene's area_lights; AREA_LIGHTS defined where one is on, app/scene/area_lights.py):
// spheres and one-sided rectangles of uniform radiance, all outside the volume box, so a ray from
// inside the box meets one only after it leaves the box (and a camera ray from outside may meet
// one before it enters). NumPy twin: app/twins/area_lights.py.
//
// Sampling (next-event estimation): a light chosen uniformly among the count, then a sphere's cone
// of directions uniformly (pdf 1 / (2 pi (1 - cos theta_max)) over solid angle, 1 - cos theta_max
// written as sin^2 / (1 + cos) so a small far light keeps its precision), or a rectangle's area
// uniformly (pdf t^2 / (A cos theta_light) over solid angle; its back face emits nothing). A
// direction's pdf is the chosen light's where that light is the first one the direction meets
// (another light in front occludes it), divided by the count: the same for a direction the path
// drew itself and hit a light with, which is what the MIS weights of both sides need.
const int AREA_LIGHTS_MAX = 8;
const int AREA_LIGHT_SPHERE = 0;
uniform int area_light_count;                           // lights on (1 .. AREA_LIGHTS_MAX)
uniform int area_light_shape[AREA_LIGHTS_MAX];          // 0 sphere, 1 rectangle
uniform vec3 area_light_position[AREA_LIGHTS_MAX];      // centre
uniform vec3 area_light_u[AREA_LIGHTS_MAX];             // sphere: (radius, 0, 0); rectangle:
uniform vec3 area_light_v[AREA_LIGHTS_MAX];             //   half edges, normal along u x v
uniform vec3 area_light_radiance[AREA_LIGHTS_MAX];      // colour x strength

// Distance along the ray x + t w (w unit) to light i, or -1 where it misses.
float area_light_distance(int i, vec3 x, vec3 w)
{
    vec3 c = area_light_position[i];
    if (area_light_shape[i] == AREA_LIGHT_SPHERE) {
        float r = area_light_u[i].x;
        vec3 oc = x - c;
        float b = dot(oc, w);
        vec3 perp = oc - b * w;                  // centre to the ray's closest point, stably
        float disc = r * r - dot(perp, perp);
        if (disc < 0.0)
            return -1.0;
        float t = -b - sqrt(disc);
        return t > 0.0 ? t : -1.0;
    }
    vec3 u = area_light_u[i], v = area_light_v[i];
    vec3 n = cross(u, v);
    float denom = dot(w, n);
    if (denom == 0.0)
        return -1.0;
    float t = dot(c - x, n) / denom;
    if (!(t > 0.0))
        return -1.0;
    vec3 q = x + t * w - c;
    float s = dot(q, u) / dot(u, u), r = dot(q, v) / dot(v, v);
    return abs(s) <= 1.0 && abs(r) <= 1.0 ? t : -1.0;
}

// The first light the ray x + t w meets (-1: none), and its distance.
int area_light_first_hit(vec3 x, vec3 w, out float t_hit)
{
    int hit = -1;
    t_hit = 1e30;
    for (int i = 0; i < area_light_count; ++i) {
        float t = area_light_distance(i, x, w);
        if (t > 0.0 && t < t_hit) {
            t_hit = t;
            hit = i;
        }
    }
    return hit;
}

// The radiance light i sends back along -w (w the ray's direction as it arrives): a rectangle's
// back face sends none.
vec3 area_light_emitted(int i, vec3 w)
{
    if (area_light_shape[i] != AREA_LIGHT_SPHERE
        && dot(w, cross(area_light_u[i], area_light_v[i])) >= 0.0)
        return vec3(0.0);
    return area_light_radiance[i];
}

// 1 - cos theta_max of the cone a sphere light fills seen from x (sin^2 / (1 + cos)).
float area_light_cone(int i, vec3 x, out vec3 axis, out float cos_max)
{
    vec3 d = area_light_position[i] - x;
    float dist2 = dot(d, d);
    float r = area_light_u[i].x;
    float sin2 = min(r * r / dist2, 1.0);
    cos_max = sqrt(max(1.0 - sin2, 0.0));
    axis = d * inversesqrt(dist2);
    return sin2 / (1.0 + cos_max);
}

// The solid-angle pdf of drawing direction w from x by area_light_sample, given that w first
// meets light i at distance t (the count's share included).
float area_light_pdf(int i, vec3 x, vec3 w, float t)
{
    float pdf;
    if (area_light_shape[i] == AREA_LIGHT_SPHERE) {
        vec3 axis;
        float cos_max;
        pdf = 1.0 / (2.0 * PI * area_light_cone(i, x, axis, cos_max));
    } else {
        vec3 n = cross(area_light_u[i], area_light_v[i]);
        float area4 = length(n);                      // |u x v| = a quarter of the area
        float cos_light = abs(dot(w, n)) / area4;
        pdf = cos_light > 0.0 ? t * t / (4.0 * area4 * cos_light) : 0.0;
    }
    return pdf / float(area_light_count);
}

// A direction from x towards a light (u0 picks the light, u1 and u2 the point): its radiance
// (0 where it meets another light first, or a rectangle's back) and its solid-angle pdf.
vec3 area_light_sample(vec3 x, float u0, float u1, float u2, out vec3 radiance, out float pdf)
{
    int i = min(int(u0 * float(area_light_count)), area_light_count - 1);
    vec3 w;
    if (area_light_shape[i] == AREA_LIGHT_SPHERE) {
        vec3 axis;
        float cos_max;
        float one_minus_cos = area_light_cone(i, x, axis, cos_max);
        float a = u1 * one_minus_cos;               // 1 - cos theta
        float cos_t = 1.0 - a;
        float sin_t = sqrt(max(a * (2.0 - a), 0.0));
        float phi = 2.0 * PI * u2;
        vec3 b1, b2;
        orthonormal_basis(axis, b1, b2);
        w = normalize(sin_t * (cos(phi) * b1 + sin(phi) * b2) + cos_t * axis);
    } else {
        vec3 p = area_light_position[i] + (2.0 * u1 - 1.0) * area_light_u[i]
                 + (2.0 * u2 - 1.0) * area_light_v[i];
        w = normalize(p - x);
    }
    float t;
    int hit = area_light_first_hit(x, w, t);
    if (hit != i) {
        radiance = vec3(0.0);                        // another light in front (or a grazing miss)
        pdf = 0.0;
        return w;
    }
    radiance = area_light_emitted(i, w);
    pdf = area_light_pdf(i, x, w, t);
    return w;
}
