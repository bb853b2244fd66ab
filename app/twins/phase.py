"""NumPy twin of glsl/lib/phase.glsl: the Henyey-Greenstein phase function and its sampling."""
from __future__ import annotations

import numpy as np

from radiance_probes.scene.basis import orthonormal_basis  # noqa: F401  (phase.glsl builds it too)

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


def sample_hg(direction: np.ndarray, g: float, u1, u2) -> np.ndarray:
    cos_t = sample_hg_cos_theta(u1, g)[..., None]
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = 2.0 * np.pi * np.asarray(u2, np.float64)[..., None]
    b1, b2 = orthonormal_basis(direction)
    v = sin_t * (np.cos(phi) * b1 + np.sin(phi) * b2) + cos_t * np.asarray(direction, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def hg_primary_sample(direction: np.ndarray, g: float, w: np.ndarray) -> np.ndarray:
    """The inverse of sample_hg: (..., 2) points (u1, u2) of the unit square that sample_hg maps
    to the unit vectors w (..., 3) about `direction` (u1: HG's CDF at cos theta, u2: the azimuth
    over 2 pi, in [0, 1))."""
    direction = np.asarray(direction, np.float64)
    w = np.asarray(w, np.float64)
    cos_t = np.clip(np.sum(w * direction, axis=-1), -1.0, 1.0)
    if abs(g) < 1e-3:
        u1 = 0.5 * (1.0 - cos_t)
    else:
        s = np.sqrt(np.maximum((1.0 - g) ** 2 + 2.0 * g * (1.0 - cos_t), 1e-24))
        u1 = ((1.0 - g * g) / s - (1.0 - g)) / (2.0 * g)
    b1, b2 = orthonormal_basis(np.broadcast_to(direction, w.shape))
    u2 = np.arctan2(np.sum(w * b2, axis=-1), np.sum(w * b1, axis=-1)) / (2.0 * np.pi)
    u2 = np.where(u2 < 0.0, u2 + 1.0, u2)
    return np.stack([np.clip(u1, 0.0, 1.0), np.clip(u2, 0.0, 1.0)], axis=-1)
