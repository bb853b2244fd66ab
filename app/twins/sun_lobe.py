"""NumPy twin of glsl/lib/sun_lobe.glsl: the probes' lobe about the sun's direction beside their SH
bands (derivation there)."""
from __future__ import annotations

import numpy as np

from .phase import INV_4PI, phase_hg as hg


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



def lobe_amplitudes(mu, radiance, valid, hs, g, n):
    """glsl/sun_lobe_fit.comp: each probe's lobe amplitude for each candidate h, as the bake
    estimates it from one pass's walks. mu (P, D): each walk's direction . sun; radiance (P, D, 3);
    valid (P, D). Returns amplitudes (P, len(hs), 3) and walks used (P,)."""
    mu = np.asarray(mu, np.float64)
    radiance = np.where(np.asarray(valid, bool)[..., None], np.asarray(radiance, np.float64), 0.0)
    count = np.sum(valid, axis=1).astype(np.float64)
    out = np.zeros((mu.shape[0], len(hs), 3))
    for k, h in enumerate(hs):
        s = np.sum(radiance * basis(mu, h, n, g)[..., None], axis=1)
        out[:, k] = np.where(count[:, None] > 0, 4.0 * np.pi * s / np.maximum(count, 1)[:, None], 0.0)
    return out, count


def fit_gains(a, b, hs, g, n, pilot_walks, main_walks):
    """What each candidate lobe takes out of the error the renderers see, summed over probes and
    colours, less the noise its amplitude adds in a bake of `main_walks` walks per probe: a and b
    (P, K, 3) are two independent passes' amplitudes of `pilot_walks` walks each. The error
    removed is A^2 <r_gh, r_gh> (A the true amplitude; lib/sun_lobe.glsl), estimated without bias
    by a b <r_gh, r_gh>; the bake's amplitude has the variance of one pass's times pilot_walks /
    main_walks, one pass's estimated as (a - b)^2 / 2."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    norms = np.array([norm(g * h, n) for h in hs])
    explained = np.sum(a * b, axis=(0, 2))
    noise = 0.5 * np.sum((a - b) ** 2, axis=(0, 2)) * pilot_walks / main_walks
    return norms * (explained - noise)
