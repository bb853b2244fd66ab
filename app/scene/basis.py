"""The orthonormal basis of unit vectors (Duff et al. 2017): a rectangle light's edges lie along
it, and glsl/lib/phase.glsl builds the same basis around a direction (app/twins/phase.py, its twin,
takes it from here)."""
from __future__ import annotations

import numpy as np


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Duff et al. 2017, for an array of unit vectors (..., 3)."""
    n = np.asarray(n, np.float64)
    s = np.where(n[..., 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (s + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    b1 = np.stack([1.0 + s * n[..., 0] ** 2 * a, s * b, -s * n[..., 0]], axis=-1)
    b2 = np.stack([b, s + n[..., 1] ** 2 * a, -n[..., 1]], axis=-1)
    return b1, b2
