"""NumPy twin of glsl/lib/segment_sun.glsl: the sun's single scattering over one raymarch segment
with constant sigma_t and the sun's optical depth linear along it."""
from __future__ import annotations

import numpy as np


def segment_sun_weight(sigma_t, dt, tau_start, tau_end):
    """integral_0^dt sigma_t exp(-sigma_t s) exp(-tau(s)) ds, tau linear from tau_start to tau_end
    (float64; arrays broadcast)."""
    sigma_t, dt = np.asarray(sigma_t, np.float64), np.asarray(dt, np.float64)
    tau_start, tau_end = np.asarray(tau_start, np.float64), np.asarray(tau_end, np.float64)
    a = sigma_t * dt
    x = a + (tau_end - tau_start)
    small = np.abs(x) < 1e-3
    safe = np.where(small, 1.0, x)
    exact = a * (np.exp(-tau_start) - np.exp(-(tau_end + a))) / safe
    series = a * np.exp(-tau_start) * (1.0 - x * (0.5 - x / 6.0))
    return np.where(small, series, exact)
