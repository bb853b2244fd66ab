"""NumPy twin of glsl/lib/phase.glsl: the Henyey-Greenstein phase function and its sampling."""
from __future__ import annotations

import numpy as np

INV_4PI = 1.0 / (4.0 * np.pi)


def phase_hg(cos_theta, g: float) -> np.ndarray:
    """HG density over the sphere; cos_theta between propagation directions before and after."""
    cos_theta = np.asarray(cos_theta, np.float64)
    denom = (1.0 - g) ** 2 + 2.0 * g * (1.0 - cos_theta)
    return INV_4PI * (1.0 - g * g) / (denom * np.sqrt(np.maximum(denom, 1e-12)))


def sample_hg_cos_theta(u, g: float) -> np.ndarray:
    """Inverse CDF of HG in cos_theta for u in [0, 1)."""
    u = np.asarray(u, np.float64)
    if abs(g) < 1e-3:
        return 1.0 - 2.0 * u
    s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
    return np.clip((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0)


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Duff et al. 2017, for an array of unit vectors (..., 3)."""
    n = np.asarray(n, np.float64)
    s = np.where(n[..., 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (s + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    b1 = np.stack([1.0 + s * n[..., 0] ** 2 * a, s * b, -s * n[..., 0]], axis=-1)
    b2 = np.stack([b, s + n[..., 1] ** 2 * a, -n[..., 1]], axis=-1)
    return b1, b2


def sample_hg(direction: np.ndarray, g: float, u1, u2) -> np.ndarray:
    cos_t = sample_hg_cos_theta(u1, g)[..., None]
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = 2.0 * np.pi * np.asarray(u2, np.float64)[..., None]
    b1, b2 = orthonormal_basis(direction)
    v = sin_t * (np.cos(phi) * b1 + np.sin(phi) * b2) + cos_t * np.asarray(direction, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)
