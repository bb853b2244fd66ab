"""NumPy twin of glsl/lib/sh.glsl: real orthonormal spherical harmonics up to l = 4.

Convention (Sloan, "Stupid Spherical Harmonics (SH) Tricks", GDC 2008), for a unit vector w:
index k = l*(l+1) + m, order (0,0) (1,-1) (1,0) (1,1) (2,-2) (2,-1) (2,0) (2,1) (2,2); no
Condon-Shortley phase, so Y1-1 = +sqrt(3/(4pi)) y, Y10 = +sqrt(3/(4pi)) z, Y11 = +sqrt(3/(4pi)) x.

Coefficient arrays have shape (K,) (scalar signal) or (K, C) (e.g. C = 3 for RGB), K = (order + 1)^2
for order 2 (9, the default), 3 (16) or 4 (25); the band is implied by K.
"""
from __future__ import annotations

import numpy as np
from numpy.polynomial.legendre import leggauss

SH_COUNT = 9          # order 2
SH_MAX_ORDER = 4
SH_C0 = np.sqrt(1.0 / (4.0 * np.pi))
SH_C1 = np.sqrt(3.0 / (4.0 * np.pi))
SH_C2 = np.sqrt(15.0 / (4.0 * np.pi))
SH_C20 = np.sqrt(5.0 / (16.0 * np.pi))
SH_C22 = np.sqrt(15.0 / (16.0 * np.pi))
SH_C33 = np.sqrt(35.0 / (32.0 * np.pi))
SH_C32 = np.sqrt(105.0 / (4.0 * np.pi))
SH_C31 = np.sqrt(21.0 / (32.0 * np.pi))
SH_C30 = np.sqrt(7.0 / (16.0 * np.pi))
SH_C32B = np.sqrt(105.0 / (16.0 * np.pi))
SH_C44 = 0.75 * np.sqrt(35.0 / np.pi)
SH_C43 = 0.75 * np.sqrt(35.0 / (2.0 * np.pi))
SH_C42 = 0.75 * np.sqrt(5.0 / np.pi)
SH_C41 = 0.75 * np.sqrt(5.0 / (2.0 * np.pi))
SH_C40 = 3.0 / 16.0 * np.sqrt(1.0 / np.pi)
SH_C42B = 3.0 / 8.0 * np.sqrt(5.0 / np.pi)
SH_C44B = 3.0 / 16.0 * np.sqrt(35.0 / np.pi)

SH_WINDOW_NONE, SH_WINDOW_HANN, SH_WINDOW_LANCZOS = 0, 1, 2


def sh_count(order: int) -> int:
    """Coefficients of bands 0 .. order."""
    return (order + 1) ** 2


def sh_band(count: int) -> np.ndarray:
    """Band l of each of `count` coefficients (count a square)."""
    return np.floor(np.sqrt(np.arange(count) + 0.5)).astype(int)


SH_BAND = sh_band(9)  # band l of coefficient k, order 2


def _order_of(count: int) -> int:
    order = int(round(np.sqrt(count))) - 1
    if sh_count(order) != count or not 0 <= order <= SH_MAX_ORDER:
        raise ValueError(f"{count} SH coefficients: expected (order + 1)^2 for order 0 .. {SH_MAX_ORDER}")
    return order


def sh_basis(w, order: int = 2) -> np.ndarray:
    """The (order + 1)^2 basis functions at unit directions w (..., 3); returns (..., K)."""
    if not 0 <= order <= SH_MAX_ORDER:
        raise ValueError(f"SH order {order}: expected 0 .. {SH_MAX_ORDER}")
    w = np.asarray(w, np.float64)
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    x2, y2, z2 = x * x, y * y, z * z
    functions = [
        np.full_like(x, SH_C0),
        SH_C1 * y, SH_C1 * z, SH_C1 * x,
        SH_C2 * x * y, SH_C2 * y * z, SH_C20 * (3.0 * z2 - 1.0), SH_C2 * x * z,
        SH_C22 * (x2 - y2),
        SH_C33 * y * (3.0 * x2 - y2), SH_C32 * x * y * z, SH_C31 * y * (5.0 * z2 - 1.0),
        SH_C30 * z * (5.0 * z2 - 3.0), SH_C31 * x * (5.0 * z2 - 1.0), SH_C32B * z * (x2 - y2),
        SH_C33 * x * (x2 - 3.0 * y2),
        SH_C44 * x * y * (x2 - y2), SH_C43 * y * z * (3.0 * x2 - y2),
        SH_C42 * x * y * (7.0 * z2 - 1.0), SH_C41 * y * z * (7.0 * z2 - 3.0),
        SH_C40 * (35.0 * z2 * z2 - 30.0 * z2 + 3.0), SH_C41 * x * z * (7.0 * z2 - 3.0),
        SH_C42B * (x2 - y2) * (7.0 * z2 - 1.0), SH_C43 * x * z * (x2 - 3.0 * y2),
        SH_C44B * (x2 * (x2 - 3.0 * y2) - y2 * (3.0 * x2 - y2)),
    ]
    return np.stack(functions[:sh_count(order)], axis=-1)


def sh_evaluate(coeffs, w) -> np.ndarray:
    """sum_k c_k Y_k(w): shape (...) for coeffs (K,), (..., C) for coeffs (K, C)."""
    c = np.asarray(coeffs, np.float64)
    return sh_basis(w, _order_of(len(c))) @ c


def sh_band_factors(g: float, window: int, order: int = 2) -> np.ndarray:
    """Per-band multipliers window_l * g^l for l = 0 .. order.

    Windows against ringing (Sloan 2008), width w = order + 1 (3 for order 2):
    Hann window_l = (1 + cos(pi l / w)) / 2; Lanczos sigma window_l = sinc(l / w).
    """
    bands = order + 1
    l = np.arange(bands, dtype=np.float64)
    if window == SH_WINDOW_NONE:
        window_l = np.ones(bands)
    elif window == SH_WINDOW_HANN:
        window_l = 0.5 * (1.0 + np.cos(np.pi * l / bands))
    elif window == SH_WINDOW_LANCZOS:
        window_l = np.sinc(l / bands)  # sin(pi x) / (pi x)
    else:
        raise ValueError(f"unknown SH window {window}")
    return window_l * float(g) ** l


def sh_evaluate_convolved(coeffs, w, band_factors) -> np.ndarray:
    """sum_l band_factors[l] sum_m c_lm Y_lm(w), not clamped.

    Probes store incident radiance L_in(omega): the radiance arriving at the probe FROM omega
    (light travelling along -omega). A camera ray travelling along d sees the in-scattered radiance

        L_s(d) = integral_sphere p_HG(dot(omega, d)) L_in(omega) d omega,
        p_HG(cos) = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos)^1.5)   (app/twins/phase.py phase_hg),

    since the angle between the propagation directions -omega and -d has cosine dot(omega, d).
    HG is a zonal kernel with Legendre expansion sum_l (2l+1)/(4pi) g^l P_l, so by Funk-Hecke
    L_s(d) = sum_lm g^l c_lm Y_lm(d): band_factors = sh_band_factors(g, window, order). The
    identity is exact when L_in is band-limited to l <= order.
    """
    c = np.asarray(coeffs, np.float64)
    f = np.asarray(band_factors, np.float64)[sh_band(len(c))]
    return sh_evaluate(c * f.reshape((len(c),) + (1,) * (c.ndim - 1)), w)


def sh_clamp_nonnegative(radiance) -> np.ndarray:
    return np.maximum(radiance, 0.0)


def sh_project_samples(directions, values, order: int = 2) -> np.ndarray:
    """Monte-Carlo / equal-weight projection 4pi/N sum_i values_i Y(directions_i).

    directions (N, 3), values (N,) or (N, C); returns (K,) or (K, C).
    """
    directions = np.asarray(directions, np.float64)
    values = np.asarray(values, np.float64)
    return (4.0 * np.pi / len(directions)) * np.tensordot(sh_basis(directions, order), values,
                                                         axes=(0, 0))


def sphere_quadrature(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Directions (M, 3) and weights (M,) summing to 4pi.

    Gauss-Legendre in z = cos(theta) with n nodes on each hemisphere, z in [-1, 0] and [0, 1]
    (so a kink at the horizon, as in max(0, z), integrates exactly), times 2n uniform phi.
    Exact for spherical polynomials of degree <= 2n - 1 on each hemisphere.
    """
    t, wt = leggauss(n)
    z = np.concatenate([0.5 * (t - 1.0), 0.5 * (t + 1.0)])
    wz = np.concatenate([0.5 * wt, 0.5 * wt])
    m = 2 * n
    phi = (np.arange(m) + 0.5) * (2.0 * np.pi / m)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    dirs = np.stack([
        sin_t[:, None] * np.cos(phi)[None, :],
        sin_t[:, None] * np.sin(phi)[None, :],
        np.broadcast_to(z[:, None], (2 * n, m)),
    ], axis=-1).reshape(-1, 3)
    weights = np.broadcast_to((wz * (2.0 * np.pi / m))[:, None], (2 * n, m)).reshape(-1)
    return dirs, weights


def sh_project_function(f, n: int = 32, order: int = 2) -> np.ndarray:
    """c_k = integral f(w) Y_k(w) dw by sphere_quadrature(n); f maps (M, 3) to (M,) or (M, C)."""
    dirs, weights = sphere_quadrature(n)
    values = np.asarray(f(dirs), np.float64)
    return np.tensordot(sh_basis(dirs, order) * weights[:, None], values, axes=(0, 0))
