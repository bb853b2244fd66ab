"""NumPy twin of glsl/lib/guided_directions.glsl: `guided`'s next direction drawn by one-sample
MIS between Henyey-Greenstein and HG times the probes' radiance, tabulated in sample_hg's unit
square (pdf(w) = p_HG(w) q(u(w)), q = (1 - P) + P N m_k / M; the GLSL file derives it)."""
from __future__ import annotations

import numpy as np

from .phase import hg_primary_sample, orthonormal_basis, phase_hg, sample_hg, sample_hg_cos_theta
from .sh import sh_band, sh_band_factors, sh_basis

CELLS_COS = 8
CELLS_PHI = 8
CELLS = CELLS_COS * CELLS_PHI
CELL_FLOOR = 0.05
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def cell_centre_directions(w_in, g: float) -> np.ndarray:
    """The (CELLS, 3) directions sample_hg maps the cells' centres to, cell k = row * CELLS_PHI
    + column."""
    w_in = np.asarray(w_in, np.float64)
    cos_t = sample_hg_cos_theta((np.arange(CELLS_COS) + 0.5) / CELLS_COS, g)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = 2.0 * np.pi * (np.arange(CELLS_PHI) + 0.5) / CELLS_PHI
    b1, b2 = orthonormal_basis(w_in)
    w = (sin_t[:, None, None] * (np.cos(phi)[None, :, None] * b1 + np.sin(phi)[None, :, None] * b2)
         + cos_t[:, None, None] * w_in)
    return w.reshape(CELLS, 3)


def direction_table(coeffs, w_in, g: float, window: int, order: int = 2) -> np.ndarray:
    """The table's running sums (CELLS,) at an event reached along w_in; coeffs (SH_COUNT, 3).
    The window is the renderer's (app/rendering/probes.py band_factors): max(order, 2) + 1 wide."""
    c = np.asarray(coeffs, np.float64)
    factors = sh_band_factors(1.0, window, max(order, 2))[sh_band(len(c))]
    luminance = factors * (c @ LUMINANCE)
    h = np.maximum(sh_basis(cell_centre_directions(w_in, g), order) @ luminance, 0.0)
    total = h.sum()
    masses = np.maximum(h, CELL_FLOOR * total / CELLS) if total > 0.0 else np.ones(CELLS)
    return np.cumsum(masses)


def direction_cell(u) -> np.ndarray:
    u = np.asarray(u, np.float64)
    row = np.clip((u[..., 0] * CELLS_COS).astype(int), 0, CELLS_COS - 1)
    column = np.clip((u[..., 1] * CELLS_PHI).astype(int), 0, CELLS_PHI - 1)
    return row * CELLS_PHI + column


def primary_density(cdf, u, probability: float) -> np.ndarray:
    """q(u) for points u (..., 2) of the unit square."""
    cdf = np.asarray(cdf, np.float64)
    masses = np.diff(cdf, prepend=0.0)
    return 1.0 - probability + probability * CELLS * masses[direction_cell(u)] / cdf[-1]


def sample_primary(cdf, probability: float, xi_choice, xi1, xi2) -> np.ndarray:
    """Points (..., 2) drawn from q with three uniform numbers each (as the GLSL draws them)."""
    cdf = np.asarray(cdf, np.float64)
    xi_choice, xi1, xi2 = (np.asarray(v, np.float64) for v in (xi_choice, xi1, xi2))
    table = xi_choice < probability
    target = np.minimum(xi_choice / max(probability, 1e-300), 1.0) * cdf[-1]
    cell = np.minimum(np.searchsorted(cdf, target, side="right"), CELLS - 1)
    row, column = cell // CELLS_PHI, cell % CELLS_PHI
    u1 = np.where(table, (row + xi1) / CELLS_COS, xi1)
    u2 = np.where(table, (column + xi2) / CELLS_PHI, xi2)
    return np.stack([u1, u2], axis=-1)


def sample_direction(coeffs, w_in, g: float, window: int, order: int, probability: float,
                     xi_choice, xi1, xi2) -> tuple[np.ndarray, np.ndarray]:
    """Directions (..., 3) and their path weights phase / pdf = 1 / q (...)."""
    cdf = direction_table(coeffs, w_in, g, window, order)
    u = sample_primary(cdf, probability, xi_choice, xi1, xi2)
    w_in = np.broadcast_to(np.asarray(w_in, np.float64), u.shape[:-1] + (3,))
    return sample_hg(w_in, g, u[..., 0], u[..., 1]), 1.0 / primary_density(cdf, u, probability)


def direction_pdf(coeffs, w_in, g: float, window: int, order: int, probability: float,
                  w) -> np.ndarray:
    """The mixture's density over the sphere at unit vectors w (..., 3): p_HG(w) q(u(w))."""
    cdf = direction_table(coeffs, w_in, g, window, order)
    w = np.asarray(w, np.float64)
    w_in = np.asarray(w_in, np.float64)
    u = hg_primary_sample(w_in, g, w)
    return phase_hg(w @ w_in, g) * primary_density(cdf, u, probability)
