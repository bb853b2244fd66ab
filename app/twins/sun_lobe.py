"""NumPy twin of glsl/lib/sun_lobe.glsl: the probes' lobe about the sun's direction beside their SH
bands (derivation there)."""
from __future__ import annotations

import numpy as np

from radiance_probes.twins.phase import INV_4PI, phase_hg as hg


def low_bands(mu, x, n):
    """sum_{l<=n} (2l+1)/(4 pi) x^l P_l(mu)."""
    mu = np.asarray(mu, np.float64)
    return INV_4PI * np.polynomial.legendre.legval(mu, [(2 * l + 1) * x ** l for l in range(n + 1)])


def residual(mu, x, n):
    return hg(mu, x) - low_bands(mu, x, n)


def norm(h, n):
    x = h * h
    return INV_4PI * ((1.0 + x) / (1.0 - x) ** 2 - sum((2 * l + 1) * x ** l for l in range(n + 1)))


def basis(mu, h, n, g):
    """What the walks are projected onto for phase-function g: HG_{g^2 h} above band n over
    <r_gh, r_gh> (the amplitude that minimises the error the renderers see)."""
    return residual(mu, g * g * h, n) / norm(g * h, n)


def convolved(mu, g, h, n):
    return residual(mu, g * h, n)
