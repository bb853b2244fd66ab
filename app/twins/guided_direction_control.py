"""NumPy twin of glsl/lib/guided_direction_control.glsl: `guided`'s control variate on a scattering
event's direction, the probes' radiance expected over the phase function minus their radiance in
the direction drawn times its path weight phase / pdf (mean 0 over the pdf at any coefficients,
by Funk-Hecke)."""
from __future__ import annotations

import numpy as np

from radiance_probes.twins.sh import sh_band_factors, sh_evaluate_convolved


def direction_control(coeffs, w_in, w, g: float, window: int, order: int = 2,
                      phase_over_pdf=1.0) -> np.ndarray:
    """coeffs (SH_COUNT, 3); w_in, w (..., 3) unit vectors: w_in the direction the path arrived
    along, w the one drawn about it with density pdf (Henyey-Greenstein g: phase_over_pdf 1;
    another pdf: phase / pdf), phase_over_pdf broadcasting
    against w's (...). Returns (..., 3)."""
    expected = sh_evaluate_convolved(coeffs, w_in, sh_band_factors(g, window, order))
    drawn = sh_evaluate_convolved(coeffs, w, sh_band_factors(1.0, window, order))
    weight = np.asarray(phase_over_pdf, np.float64)[..., None]
    return np.asarray(expected) - np.asarray(drawn) * weight
