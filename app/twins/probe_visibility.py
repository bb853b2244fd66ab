"""NumPy twin of glsl/lib/probe_visibility.glsl: the visibility-weighted blend of the 8 probes
around a point (probes.interpolation "visibility").

Probe i's trilinear weight w_i is scaled by v_i = exp(-(e_i - min_j e_j)) with
e_i = max(0, tau_i - sigma_t(x) |p_i - x|), tau_i the optical depth of the segment from x to the
probe from `samples` midpoint samples; the weights are renormalised. `occluded` says whether some
v_i fell below 1 - tolerance (the shader then blends with these weights, else trilinearly).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

TOLERANCE = 0.01   # PROBE_VISIBILITY_TOLERANCE
SAMPLES = 1        # PROBE_VISIBILITY_SAMPLES' default

# corner c of a cell: (c & 1, (c >> 1) & 1, c >> 2), as in the shader
CORNERS = np.array([(c & 1, (c >> 1) & 1, c >> 2) for c in range(8)], np.int64)


def excess_optical_depth(sigma_t: Callable[[np.ndarray], np.ndarray], x: np.ndarray,
                         sigma_x: np.ndarray, p: np.ndarray, samples: int = SAMPLES) -> np.ndarray:
    """e above for points x (..., 3) and probes p (..., 3); sigma_t maps world points to
    extinction."""
    segment = p - x
    total = np.zeros(x.shape[:-1])
    for j in range(samples):
        total += sigma_t(x + ((j + 0.5) / samples) * segment)
    return np.maximum(np.linalg.norm(segment, axis=-1) * (total / samples - sigma_x), 0.0)


def corner_weights(x: np.ndarray, uvw: np.ndarray, grid, box_size, probe_position: Callable,
                   sigma_t: Callable[[np.ndarray], np.ndarray], majorant: float,
                   max_cell: float = 1.0, samples: int = SAMPLES, tolerance: float = TOLERANCE):
    """For points x (n, 3) at probe-texture coordinates uvw (n, 3) of a grid over a probe box of
    size box_size: the corners' probe indices (n, 8, 3) (clamped to the grid), their normalised
    weights (n, 8), and `occluded` (n,). probe_position maps integer (i, j, k) (..., 3) to world
    positions; majorant bounds sigma_t; max_cell is the widest spacing over the uniform one."""
    grid = np.asarray(grid, np.int64)
    c = np.asarray(uvw, np.float64) * grid - 0.5
    lower = np.floor(c)
    f = c - lower
    ijk = np.clip(lower.astype(np.int64)[:, None, :] + CORNERS[None], 0, grid - 1)
    sigma_x = sigma_t(x)
    spacing = np.asarray(box_size, np.float64) / grid
    # the shader's early out: no way can move a weight past the tolerance
    possible = max_cell * np.linalg.norm(spacing) * (majorant - sigma_x) >= tolerance
    excess = np.stack([excess_optical_depth(sigma_t, x, sigma_x, probe_position(ijk[:, k]), samples)
                       for k in range(8)], axis=1)
    visibility = np.where(possible[:, None], np.exp(excess.min(axis=1, keepdims=True) - excess), 1.0)
    w3 = np.where(CORNERS[None] == 1, f[:, None, :], 1.0 - f[:, None, :])
    weights = w3.prod(axis=-1) * visibility
    total = weights.sum(axis=1, keepdims=True)
    occluded = (visibility < 1.0 - tolerance).any(axis=1) & (total[:, 0] > 0)
    weights = np.where(total > 0, weights / np.where(total > 0, total, 1.0), weights)
    return ijk, weights, occluded


def blend(values: np.ndarray, ijk: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The probes' values (nz, ny, nx, ...) at the corners' weights: (n, ...)."""
    picked = values[ijk[..., 2], ijk[..., 1], ijk[..., 0]]          # (n, 8, ...)
    w = weights.reshape(weights.shape + (1,) * (picked.ndim - 2))
    return (w * picked).sum(axis=1)
