// Henyey-Greenstein phase function. cos_theta is the cosine between the direction light travels
// before and after scattering (both as propagation directions): g > 0 scatters forward.
// The function is reciprocal, so a path traced from the camera uses the same expression.
// NumPy twin: app/twins/phase.py.
const float PI = 3.14159265358979323846;
const float INV_4PI = 0.07957747154594767;

float phase_hg(float cos_theta, float g)
{
    // 1 + g^2 - 2 g cos written without cancellation near cos = 1 for g -> 1
    float denom = (1.0 - g) * (1.0 - g) + 2.0 * g * (1.0 - cos_theta);
    return INV_4PI * (1.0 - g * g) / (denom * sqrt(max(denom, 1e-12)));
}

// Inverse CDF of HG in cos_theta, for u in [0, 1).
float sample_hg_cos_theta(float u, float g)
{
    if (abs(g) < 1e-3)
        return 1.0 - 2.0 * u;
    float s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
    return clamp((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0);
}

// Orthonormal basis around a unit vector (Duff et al. 2017).
void orthonormal_basis(vec3 n, out vec3 b1, out vec3 b2)
{
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    float b = n.x * n.y * a;
    b1 = vec3(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    b2 = vec3(b, s + n.y * n.y * a, -n.y);
}

// A new propagation direction after scattering a ray travelling along `direction`.
vec3 sample_hg(vec3 direction, float g, float u1, float u2)
{
    float cos_theta = sample_hg_cos_theta(u1, g);
    float sin_theta = sqrt(max(0.0, 1.0 - cos_theta * cos_theta));
    float phi = 2.0 * PI * u2;
    vec3 b1, b2;
    orthonormal_basis(direction, b1, b2);
    return normalize(sin_theta * (cos(phi) * b1 + sin(phi) * b2) + cos_theta * direction);
}

// The inverse of sample_hg: the point (u1, u2) of the unit square that sample_hg(direction, g,
// u1, u2) maps to the unit vector w (u1 HG's CDF at cos theta = w . direction, u2 the azimuth
// about the same basis over 2 pi, in [0, 1)). With s^2 = 1 + g^2 - 2 g cos theta (written as
// phase_hg writes it), sample_hg_cos_theta's s = (1 - g^2) / (1 - g + 2 g u1) gives
// u1 = ((1 - g^2) / s - (1 - g)) / (2 g).
vec2 hg_primary_sample(vec3 direction, float g, vec3 w)
{
    float cos_theta = clamp(dot(w, direction), -1.0, 1.0);
    float u1;
    if (abs(g) < 1e-3) {
        u1 = 0.5 * (1.0 - cos_theta);
    } else {
        float s = sqrt(max((1.0 - g) * (1.0 - g) + 2.0 * g * (1.0 - cos_theta), 1e-24));
        u1 = ((1.0 - g * g) / s - (1.0 - g)) / (2.0 * g);
    }
    vec3 b1, b2;
    orthonormal_basis(direction, b1, b2);
    float x = dot(w, b1), y = dot(w, b2);
    // (along the axis itself the azimuth is any: 0, as atan(0, 0) is left undefined)
    float u2 = x == 0.0 && y == 0.0 ? 0.0 : atan(y, x) / (2.0 * PI);
    u2 = u2 < 0.0 ? u2 + 1.0 : u2;
    return vec2(clamp(u1, 0.0, 1.0), clamp(u2, 0.0, 1.0));
}
