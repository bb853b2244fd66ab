// Hybrid scattering (Exposure Render's rule): at each real scattering event the medium scatters
// either by a surface BRDF, with probability P = 1 - exp(-k |grad A|), or by the phase function.
// NumPy twin: app/twins/hybrid_scattering.py.
//
// Compiled only where the scene's surface.gradient_factor k > 0 (HYBRID_SCATTERING, set by
// app/rendering/resources.py): k = 0 compiles every pass's code as it was, bit for bit.
//
// The gradient: of the opacity field A(x) = sigma_t(x) / density_scale (the transfer function's
// alpha at x, zero where the crop or clip plane cut the medium away: lib/medium.glsl classified_at),
// in world units (the box's longest side is 1), by central differences over one voxel along each
// axis (surface_gradient_step: the voxel's world size per axis). A does not depend on
// density_scale, so k does not either; a jump of A from 0 to 1 over one voxel of a 256-voxel side
// is |grad A| of about 128.
//
// The surface: normal n = grad A / |grad A|, turned to face v, the direction back along the
// arriving path (v = -w_in). The BRDF, for l and v both on n's side (0 otherwise: a surface point
// is lit only from the side it faces):
//   f(v, l) = (1 - s) / pi + F0 D(h) G2(v, l) / (4 (n.v) (n.l)),   s = max(F0.r, F0.g, F0.b),
// Lambertian diffuse plus a GGX specular lobe (alpha = surface_roughness, height-correlated Smith
// G2, constant Fresnel F0 = surface_specular). It scales the event's single-scattering albedo
// (albedo x the transfer function's colour) as the phase function does. Its cosine-weighted
// integral is at most 1 - s + F0 E_ggx(v) <= 1; with F0 = 0 it is exactly 1 (non-absorbing).
//
// The event's kernel, which takes the phase function's place in every estimate, is
// K(v, l) = f(v, l) (n.l). Sampling: the specular lobe with probability q = 0.5 where F0 > 0
// (else 0), drawn from the GGX distribution of visible normals (Heitz 2018) and reflected; the
// diffuse lobe otherwise, cosine-weighted. pdf(l) = q pdf_spec(l) + (1 - q) (n.l)_+ / pi, with
// pdf_spec(l) = D(h) G1(v) / (4 (n.v)), h = normalize(v + l) (0 where n.h <= 0 or v.h <= 0): each
// part integrates to 1 over the sphere, so the path weight K / pdf is exact.
uniform float surface_gradient_factor;   // k (> 0 here)
uniform float surface_roughness;         // GGX alpha, in [0.02, 1]
uniform vec3 surface_specular;           // F0 per colour, in [0, 1]
uniform vec3 surface_gradient_step;      // central-difference step along x, y, z (world units)

// grad A at x (A = classified_at(x).a = sigma_t / density_scale).
vec3 opacity_gradient(vec3 x)
{
    vec3 h = surface_gradient_step;
    vec3 g;
    g.x = classified_at(x + vec3(h.x, 0.0, 0.0)).a - classified_at(x - vec3(h.x, 0.0, 0.0)).a;
    g.y = classified_at(x + vec3(0.0, h.y, 0.0)).a - classified_at(x - vec3(0.0, h.y, 0.0)).a;
    g.z = classified_at(x + vec3(0.0, 0.0, h.z)).a - classified_at(x - vec3(0.0, 0.0, h.z)).a;
    return g / (2.0 * h);
}

// P = 1 - exp(-k |grad A|): the chance that an event at a point of this gradient is a surface's.
float surface_probability(vec3 gradient, float k)
{
    return 1.0 - exp(-k * length(gradient));
}

// The raymarcher's Russian roulette (lib/raymarch.glsl, with surfaces): below this transmittance
// a ray goes on with probability transmittance / this, carrying this transmittance, and stops
// otherwise; the expected transmittance, so every later sample's expected weight, stays what it
// was. NumPy twin: app/twins/hybrid_scattering.py hybrid_march_roulette. Its noise: a ray's rest
// R is kept as R T0 / T with chance T / T0, a standard deviation of at most T0 R / 2 (at T =
// T0 / 2), so 1% of the rest at T0 = 2e-2. The threshold is where a frame's time times its
// variance is least: on an H200 (bench/h200-hybrid-cost, the foot at 1080p) 1e-2 and 2e-2 are
// within 0.2% of each other, 1e-3 4% above them, 3e-2 1% and 1e-1 52%.
const float HYBRID_MARCH_ROULETTE_TRANSMITTANCE = 2e-2;

// The transmittance after the roulette at `transmittance` (below the threshold) with uniform u:
// the threshold where u < transmittance / threshold, else 0 (the ray stops).
float hybrid_march_roulette(float transmittance, float u)
{
    return u < transmittance / HYBRID_MARCH_ROULETTE_TRANSMITTANCE
        ? HYBRID_MARCH_ROULETTE_TRANSMITTANCE : 0.0;
}

// The unit normal along the gradient, on v's side (v: unit, back along the arriving path).
vec3 surface_normal(vec3 gradient, vec3 v)
{
    vec3 n = normalize(gradient);
    return dot(n, v) < 0.0 ? -n : n;
}

// GGX (Trowbridge-Reitz) normal distribution at cos theta_h, alpha^2 = a2.
float ggx_distribution(float n_h, float a2)
{
    float t = n_h * n_h * (a2 - 1.0) + 1.0;
    return a2 / (PI * t * t);
}

// Smith's Lambda for GGX at cos theta (> 0).
float ggx_lambda(float cos_theta, float a2)
{
    float c2 = cos_theta * cos_theta;
    float tan2 = max(1.0 - c2, 0.0) / c2;
    return 0.5 * (sqrt(1.0 + a2 * tan2) - 1.0);
}

float surface_specular_weight(vec3 f0)
{
    return max(f0.r, max(f0.g, f0.b));
}

// q: the chance the sampler draws the specular lobe.
float surface_specular_choice(vec3 f0)
{
    return surface_specular_weight(f0) > 0.0 ? 0.5 : 0.0;
}

// K(v, l) = f(v, l) (n.l), per colour; 0 where l or v is not on n's side.
vec3 surface_kernel(vec3 n, vec3 v, vec3 l, float alpha, vec3 f0)
{
    float n_l = dot(n, l), n_v = dot(n, v);
    if (n_l <= 0.0 || n_v <= 0.0)
        return vec3(0.0);
    float s = surface_specular_weight(f0);
    vec3 kernel = vec3((1.0 - s) / PI * n_l);
    if (s > 0.0) {
        // D G2 / (4 n.v) with G2 = 1 / (1 + Lambda(n.v) + Lambda(n.l)): as sqrt(1 + a2 tan^2) =
        // sqrt(c^2 (1 - a2) + a2) / c, that is D (n.l) / (2 (n.l S_v + n.v S_l)), S_c =
        // sqrt(c^2 (1 - a2) + a2), with ggx_distribution's D written in: one division where the
        // Lambdas and D took five (the twin keeps them)
        vec3 h = normalize(v + l);
        float a2 = alpha * alpha;
        float s_v = sqrt(n_v * n_v * (1.0 - a2) + a2), s_l = sqrt(n_l * n_l * (1.0 - a2) + a2);
        float n_h = dot(n, h);
        float t = n_h * n_h * (a2 - 1.0) + 1.0;
        kernel += f0 * (a2 * n_l / (2.0 * PI * t * t * (n_l * s_v + n_v * s_l)));
    }
    return kernel;
}

// The specular lobe's pdf of l (visible normals, reflected), over solid angle.
float surface_specular_pdf(vec3 n, vec3 v, vec3 l, float alpha)
{
    float n_v = dot(n, v);
    vec3 sum = v + l;
    if (n_v <= 0.0 || dot(sum, sum) <= 0.0)
        return 0.0;
    vec3 h = normalize(sum);
    float n_h = dot(n, h);
    if (n_h <= 0.0 || dot(v, h) <= 0.0)
        return 0.0;
    float a2 = alpha * alpha;
    float g1 = 1.0 / (1.0 + ggx_lambda(n_v, a2));
    return ggx_distribution(n_h, a2) * g1 / (4.0 * n_v);
}

// The sampler's pdf of l over solid angle (the mixture of both lobes).
float surface_pdf(vec3 n, vec3 v, vec3 l, float alpha, vec3 f0)
{
    float q = surface_specular_choice(f0);
    float pdf = (1.0 - q) * max(dot(n, l), 0.0) / PI;
    if (q > 0.0)
        pdf += q * surface_specular_pdf(n, v, l, alpha);
    return pdf;
}

// A direction l from the mixture: u0 picks the lobe, (u1, u2) the direction. weight = K / pdf
// (0 where l falls below the surface), pdf its density.
vec3 surface_sample(vec3 n, vec3 v, float alpha, vec3 f0, float u0, float u1, float u2,
                    out vec3 weight, out float pdf)
{
    vec3 b1, b2;
    orthonormal_basis(n, b1, b2);
    float q = surface_specular_choice(f0);
    float phi = 2.0 * PI * u2;
    vec3 l;
    if (u0 < q) {
        // visible normals of GGX (Heitz 2018) in the frame (b1, b2, n)
        vec3 v_local = vec3(dot(v, b1), dot(v, b2), dot(v, n));
        vec3 vh = normalize(vec3(alpha * v_local.x, alpha * v_local.y, v_local.z));
        float len2 = vh.x * vh.x + vh.y * vh.y;
        vec3 t1 = len2 > 0.0 ? vec3(-vh.y, vh.x, 0.0) * inversesqrt(len2) : vec3(1.0, 0.0, 0.0);
        vec3 t2 = cross(vh, t1);
        float r = sqrt(u1);
        float p1 = r * cos(phi);
        float p2 = r * sin(phi);
        float s = 0.5 * (1.0 + vh.z);
        p2 = (1.0 - s) * sqrt(max(1.0 - p1 * p1, 0.0)) + s * p2;
        vec3 nh = p1 * t1 + p2 * t2 + sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0)) * vh;
        vec3 h_local = normalize(vec3(alpha * nh.x, alpha * nh.y, max(nh.z, 0.0)));
        vec3 h = h_local.x * b1 + h_local.y * b2 + h_local.z * n;
        l = 2.0 * dot(v, h) * h - v;
    } else {
        float r = sqrt(u1);
        l = r * cos(phi) * b1 + r * sin(phi) * b2 + sqrt(max(1.0 - u1, 0.0)) * n;
    }
    if (q == 0.0) {
        // the diffuse lobe alone: K / pdf = (1 - s) exactly (a white furnace stays exact)
        pdf = max(dot(n, l), 0.0) / PI;
        weight = pdf > 0.0 ? vec3(1.0 - surface_specular_weight(f0)) : vec3(0.0);
        return l;
    }
    pdf = surface_pdf(n, v, l, alpha, f0);
    weight = pdf > 0.0 ? surface_kernel(n, v, l, alpha, f0) / pdf : vec3(0.0);
    return l;
}

#if defined(PROBE_SAMPLING)
// The radiance a surface point with normal n reflects towards v from the probes' incident
// radiance (coefficients `coeffs`, L_in arriving FROM omega), per unit of the event's albedo:
// diffuse (1 - s) / pi times the irradiance E(n) = sum_l A_l sum_m c_lm Y_lm(n), the clamped
// cosine's bands A_l = pi, 2 pi / 3, pi / 4, 0, -pi / 24 (exact for L_in band-limited to the
// probes' order: only light from n's side counts); specular F0 times the probes' radiance from the
// mirror direction r = 2 (n.v) n - v, smoothed by the same cosine lobe's normalised bands (A_l /
// pi): a wide lobe whatever the roughness, which blurs sharp highlights and takes the specular
// lobe's albedo as 1 rather than E_ggx(v) <= 1 (docs/design.md, Hybrid scattering).
vec3 surface_probe_radiance(vec3 coeffs[SH_COUNT], vec3 n, vec3 v, vec3 f0)
{
    float cosine_bands[SH_BANDS];
    const float A[5] = float[5](PI, 2.0 * PI / 3.0, PI / 4.0, 0.0, -PI / 24.0);
    for (int l = 0; l < SH_BANDS; ++l)
        cosine_bands[l] = A[l];
    vec3 irradiance = max(sh_evaluate_convolved(coeffs, n, cosine_bands), vec3(0.0));
    float s = surface_specular_weight(f0);
    vec3 radiance = (1.0 - s) / PI * irradiance;
    if (s > 0.0) {
        for (int l = 0; l < SH_BANDS; ++l)
            cosine_bands[l] = A[l] / PI;
        vec3 r = 2.0 * dot(n, v) * n - v;
        radiance += f0 * max(sh_evaluate_convolved(coeffs, r, cosine_bands), vec3(0.0));
    }
    return radiance;
}
#endif
