"""NumPy twin of glsl/lib/guided_direction_control.glsl: `guided`'s control variate on a scattering
event's direction, the probes' radiance expected over the phase function minus their radiance in
the direction drawn (mean 0 at any coefficients, by Funk-Hecke)."""
from __future__ import annotations

import numpy as np

from .sh import sh_band_factors, sh_evaluate_convolved


def direction_control(coeffs, w_in, w, g: float, window: int, order: int = 2) -> np.ndarray:
    """coeffs (SH_COUNT, 3); w_in, w (..., 3) unit vectors: w_in the direction the path arrived
    along, w the one drawn from Henyey-Greenstein g about it. Returns (..., 3)."""
    expected = sh_evaluate_convolved(coeffs, w_in, sh_band_factors(g, window, order))
    drawn = sh_evaluate_convolved(coeffs, w, sh_band_factors(1.0, window, order))
    return np.asarray(expected) - np.asarray(drawn)
