"""NumPy twin of glsl/lib/hybrid_scattering.glsl: the opacity gradient, the chance of a surface
event, the surface normal, the BRDF's kernel K = f (n.l), its sampler and pdf, and the surface's
radiance from the probes' SH coefficients. Directions are arrays (..., 3) of unit vectors."""
from __future__ import annotations

import numpy as np

from radiance_probes.twins.phase import orthonormal_basis
from radiance_probes.twins.sh import sh_evaluate_convolved

# The clamped cosine's SH bands A_l (Ramamoorthi and Hanrahan 2001), l = 0 .. 4.
COSINE_BANDS = np.array([np.pi, 2.0 * np.pi / 3.0, np.pi / 4.0, 0.0, -np.pi / 24.0])


def _dot(a, b) -> np.ndarray:
    return np.sum(np.asarray(a, np.float64) * np.asarray(b, np.float64), axis=-1)


def _normalize(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def opacity_gradient(opacity_at, x, step) -> np.ndarray:
    """grad A at points x (..., 3) by central differences over `step` (3 world lengths);
    `opacity_at(points)` gives A = sigma_t / density_scale (app/twins/medium.py classified_at's
    alpha)."""
    x = np.asarray(x, np.float64)
    out = np.empty_like(x)
    for i in range(3):
        e = np.zeros(3)
        e[i] = step[i]
        out[..., i] = (opacity_at(x + e) - opacity_at(x - e)) / (2.0 * step[i])
    return out


def surface_probability(gradient, k: float) -> np.ndarray:
    """P = 1 - exp(-k |grad A|)."""
    return 1.0 - np.exp(-k * np.linalg.norm(np.asarray(gradient, np.float64), axis=-1))


HYBRID_MARCH_ROULETTE_TRANSMITTANCE = np.float32(2e-2)   # lib/hybrid_scattering.glsl


def hybrid_march_roulette(transmittance, u) -> np.ndarray:
    """The transmittance after the raymarcher's roulette (float32 as the GPU's): the threshold
    where u < transmittance / threshold, else 0; its mean over u is the transmittance."""
    t = np.asarray(transmittance, np.float32)
    survive = np.asarray(u, np.float32) < t / HYBRID_MARCH_ROULETTE_TRANSMITTANCE
    return np.where(survive, HYBRID_MARCH_ROULETTE_TRANSMITTANCE, np.float32(0.0))


def surface_normal(gradient, v) -> np.ndarray:
    n = _normalize(gradient)
    return np.where((_dot(n, v) < 0.0)[..., None], -n, n)


def ggx_distribution(n_h, a2):
    t = n_h * n_h * (a2 - 1.0) + 1.0
    return a2 / (np.pi * t * t)


def ggx_lambda(cos_theta, a2):
    c2 = cos_theta * cos_theta
    tan2 = np.maximum(1.0 - c2, 0.0) / c2
    return 0.5 * (np.sqrt(1.0 + a2 * tan2) - 1.0)


def specular_weight(f0) -> float:
    return float(np.max(f0))


def specular_choice(f0) -> float:
    return 0.5 if specular_weight(f0) > 0.0 else 0.0


def surface_kernel(n, v, l, alpha: float, f0) -> np.ndarray:
    """K(v, l) = f(v, l) (n.l), (..., 3) per colour; 0 where l or v is not on n's side."""
    n, v, l = (np.asarray(a, np.float64) for a in (n, v, l))
    f0 = np.asarray(f0, np.float64)
    n_l, n_v = _dot(n, l), _dot(n, v)
    ok = (n_l > 0.0) & (n_v > 0.0)
    s = specular_weight(f0)
    kernel = np.repeat(((1.0 - s) / np.pi * n_l)[..., None], 3, axis=-1)
    if s > 0.0:
        with np.errstate(divide="ignore", invalid="ignore"):
            h = _normalize(v + l)
            a2 = alpha * alpha
            g2 = 1.0 / (1.0 + ggx_lambda(n_v, a2) + ggx_lambda(n_l, a2))
            spec = ggx_distribution(_dot(n, h), a2) * g2 / (4.0 * n_v)
        kernel = kernel + f0 * spec[..., None]
    return np.where(ok[..., None], kernel, 0.0)


def specular_pdf(n, v, l, alpha: float) -> np.ndarray:
    """The specular lobe's pdf of l: D(h) G1(v) / (4 n.v), h = normalize(v + l); 0 where n.v,
    n.h or v.h is not positive."""
    n, v, l = (np.asarray(a, np.float64) for a in (n, v, l))
    n_v = _dot(n, v)
    s = v + l
    with np.errstate(divide="ignore", invalid="ignore"):
        h = s / np.linalg.norm(s, axis=-1, keepdims=True)
        n_h, v_h = _dot(n, h), _dot(v, h)
        a2 = alpha * alpha
        pdf = ggx_distribution(n_h, a2) / (1.0 + ggx_lambda(n_v, a2)) / (4.0 * n_v)
    ok = (n_v > 0.0) & (_dot(s, s) > 0.0) & (n_h > 0.0) & (v_h > 0.0)
    return np.where(ok, pdf, 0.0)


def surface_pdf(n, v, l, alpha: float, f0) -> np.ndarray:
    q = specular_choice(f0)
    pdf = (1.0 - q) * np.maximum(_dot(n, l), 0.0) / np.pi
    if q > 0.0:
        pdf = pdf + q * specular_pdf(n, v, l, alpha)
    return pdf


def surface_sample(n, v, alpha: float, f0, u0, u1, u2):
    """(l, weight = K / pdf, pdf) for uniform numbers u0 (the lobe), u1, u2 (the direction)."""
    n, v = _normalize(n), np.asarray(v, np.float64)
    u0, u1, u2 = (np.asarray(u, np.float64) for u in (u0, u1, u2))
    b1, b2 = orthonormal_basis(n)
    q = specular_choice(f0)
    phi = 2.0 * np.pi * u2
    # diffuse: cosine-weighted
    r = np.sqrt(u1)
    l_diffuse = ((r * np.cos(phi))[..., None] * b1 + (r * np.sin(phi))[..., None] * b2
                 + np.sqrt(np.maximum(1.0 - u1, 0.0))[..., None] * n)
    # specular: visible normals (Heitz 2018) in the frame (b1, b2, n), reflected
    vl = np.stack([_dot(v, b1), _dot(v, b2), _dot(v, n)], axis=-1)
    vh = _normalize(np.stack([alpha * vl[..., 0], alpha * vl[..., 1], vl[..., 2]], axis=-1))
    len2 = vh[..., 0] ** 2 + vh[..., 1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = np.where((len2 > 0.0)[..., None],
                      np.stack([-vh[..., 1], vh[..., 0], np.zeros_like(len2)], axis=-1)
                      / np.sqrt(len2)[..., None], np.array([1.0, 0.0, 0.0]))
    t2 = np.cross(vh, t1)
    p1 = r * np.cos(phi)
    p2 = r * np.sin(phi)
    s = 0.5 * (1.0 + vh[..., 2])
    p2 = (1.0 - s) * np.sqrt(np.maximum(1.0 - p1 * p1, 0.0)) + s * p2
    nh = (p1[..., None] * t1 + p2[..., None] * t2
          + np.sqrt(np.maximum(1.0 - p1 * p1 - p2 * p2, 0.0))[..., None] * vh)
    hl = _normalize(np.stack([alpha * nh[..., 0], alpha * nh[..., 1], np.maximum(nh[..., 2], 0.0)],
                             axis=-1))
    h = hl[..., :1] * b1 + hl[..., 1:2] * b2 + hl[..., 2:] * n
    l_specular = 2.0 * _dot(v, h)[..., None] * h - v
    l = np.where((u0 < q)[..., None], l_specular, l_diffuse)
    if q == 0.0:
        pdf = np.maximum(_dot(n, l), 0.0) / np.pi
        weight = np.where((pdf > 0.0)[..., None], 1.0 - specular_weight(f0), 0.0)
        return l, np.broadcast_to(weight, l.shape).copy(), pdf
    pdf = surface_pdf(n, v, l, alpha, f0)
    with np.errstate(divide="ignore", invalid="ignore"):
        weight = np.where((pdf > 0.0)[..., None], surface_kernel(n, v, l, alpha, f0)
                          / pdf[..., None], 0.0)
    return l, weight, pdf


def surface_probe_radiance(coeffs, n, v, f0) -> np.ndarray:
    """The probes' light a surface point reflects towards v (per unit of albedo): (1 - s) / pi
    times the irradiance from the SH (bands scaled by A_l), plus F0 times the SH radiance from the
    mirror direction smoothed by A_l / pi; `coeffs` (SH_COUNT, 3) of lib/probes.glsl."""
    coeffs = np.asarray(coeffs, np.float64)
    bands = int(round(np.sqrt(len(coeffs))))
    cosine = COSINE_BANDS[:bands]
    f0 = np.asarray(f0, np.float64)
    irradiance = np.maximum(sh_evaluate_convolved(coeffs, n, cosine), 0.0)
    s = specular_weight(f0)
    radiance = (1.0 - s) / np.pi * irradiance
    if s > 0.0:
        r = 2.0 * _dot(n, v)[..., None] * np.asarray(n, np.float64) - v
        radiance = radiance + f0 * np.maximum(sh_evaluate_convolved(coeffs, r, cosine / np.pi),
                                              0.0)
    return radiance
