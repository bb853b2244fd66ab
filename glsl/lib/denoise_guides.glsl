// Noise-free guides for the denoiser (app/rendering/denoise/filter.py), from where a camera ray's first
// scattering event lands in expectation. NumPy twin: app/twins/denoise_guides.py.
//
// The ray is cut into the raymarcher's segments (lib/raymarch.glsl: the same step, the same
// jittered start). Segment i at x_i holds the first event with probability
//   w_i = transmittance_i * (1 - exp(-sigma_t(x_i) dt)),
// and the ray leaves the medium with none with the transmittance left, w_out. The guides are
// expectations under these weights:
//   albedo = sum_i w_i * albedo(x_i) + w_out * 1     (OSPRay's colour at the first volume event;
//                                                     a background counts as white, as OIDN asks)
//   normal = sum_i w_i * n(x_i),  n = -grad sigma_t / |grad sigma_t| (world space; 0 where flat)
// Both are smooth functions of the pixel: no Monte Carlo noise, so OIDN takes them as clean.
// The gradient is central differences of sigma_t at +-gradient_step (world units) per axis, taken
// only where w_i > GUIDE_GRADIENT_WEIGHT (six more lookups; a negligible weight needs none).
#define GUIDE_GRADIENT_WEIGHT 1e-4

vec3 guide_normal_at(vec3 x)
{
    vec3 h = vec3(gradient_step, 0.0, 0.0);
    vec3 grad = vec3(sigma_t_at(x + h.xyy) - sigma_t_at(x - h.xyy),
                     sigma_t_at(x + h.yxy) - sigma_t_at(x - h.yxy),
                     sigma_t_at(x + h.yyx) - sigma_t_at(x - h.yyx));
    float len = length(grad);
    return len > 0.0 ? -grad / len : vec3(0.0);
}

// The albedo and normal guides of one ray, `jitter` in [0, 1) placing the samples in their segments.
void guide_march(vec3 origin, vec3 d, float jitter, out vec3 albedo_guide, out vec3 normal_guide)
{
    albedo_guide = vec3(0.0);
    normal_guide = vec3(0.0);
    float t0, t1;
    if (!box_intersect(origin, d, t0, t1)) {
        albedo_guide = vec3(1.0);
        return;
    }
    int n = clamp(int(ceil((t1 - t0) / raymarch_step)), 1, 8192);
    float dt = (t1 - t0) / float(n);
    float transmittance = 1.0;
    for (int i = 0; i < n && transmittance > 1e-6; ++i) {
        vec3 x = origin + (t0 + (float(i) + jitter) * dt) * d;
        vec4 tf = classified_at(x);
        float sigma_t = sigma_t_of(tf);
        if (sigma_t <= 0.0)
            continue;
        float opacity = 1.0 - exp(-sigma_t * dt);
        float w = transmittance * opacity;
        albedo_guide += w * albedo_of(tf);
        if (w > GUIDE_GRADIENT_WEIGHT)
            normal_guide += w * guide_normal_at(x);
        transmittance *= 1.0 - opacity;
    }
    albedo_guide += vec3(transmittance);
}
