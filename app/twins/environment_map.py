"""NumPy twin of glsl/lib/environment_map.glsl: the equirectangular lookup of SPEC.md (Mitsuba 3's
`envmap` convention), the map's rotation about +y, and importance sampling from a 2D
piecewise-constant distribution (marginal and conditional CDFs over the map's pixels).

Convention (SPEC.md, to the letter): a unit direction d (from the scene towards the sky) reads the
map at u = frac(atan2(d.x, -d.z) / 2 pi), v = acos(d.y) / pi, i.e. at the continuous pixel
position (u W, v H), where pixel (row i, column j) covers [j, j + 1) x [i, i + 1) and its value sits
at its centre (j + 0.5, i + 0.5), as in an OpenGL texture (the volume's convention too). Bilinear
between centres, wrapping in u, clamped to the first and last row in v (row 0 is +y).

Mitsuba 3's envmap matches this in u (it reads column u W - 0.5); in v it reads row v (H - 1), up to
half a row from SPEC.md's v H - 0.5 towards the poles (equal at the equator). We follow SPEC.md.

The map is turned by `rotation` about +y (right-handed): radiance from world direction d is the
map's at R_y(-rotation) d.

Sampling. Each pixel gets the weight w = (integral of the bilinear luminance over the pixel) x
(the solid angle of its row band, cos(theta_i) - cos(theta_i+1)); the integral of the bilinear
interpolant over a pixel is the 3x3 stencil [1, 6, 1] / 8 (x) [1, 6, 1] / 8 of the pixel values,
so w > 0 wherever the looked-up radiance can be > 0 (the estimator stays unbiased). A row is
chosen from the marginal CDF, a column from the row's conditional CDF, and the position inside the
pixel uniformly; the density over (u, v) is p_uv = w / mean(w) and over solid angle
p = p_uv / (2 pi^2 sin(theta)). The GPU gets two textures: RGBA32F (rgb radiance, a p_uv) and R32F
CDFs ((W + 1) x (H + 1): row i < H the conditional CDF of row i, row H the marginal CDF).
"""
from __future__ import annotations

import numpy as np

# the sampling distribution is built where the map is loaded, before any GPU work
from radiance_probes.io.environment_map import (LUMINANCE, Distribution,  # noqa: F401
                                                build_distribution, pixel_weights)



def direction_to_uv(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """SPEC.md: u = frac(atan2(d.x, -d.z) / 2 pi), v = acos(d.y) / pi, for unit d (..., 3)."""
    d = np.asarray(d, np.float64)
    u = np.arctan2(d[..., 0], -d[..., 2]) / (2.0 * np.pi)
    u = u - np.floor(u)
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / np.pi
    return u, v


def uv_to_direction(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The inverse of direction_to_uv: theta = v pi from +y, phi = 2 pi u from -z towards +x."""
    theta, phi = np.pi * np.asarray(v, np.float64), 2.0 * np.pi * np.asarray(u, np.float64)
    s = np.sin(theta)
    return np.stack([s * np.sin(phi), np.cos(theta), -s * np.cos(phi)], axis=-1)


def rotate_y(d: np.ndarray, degrees: float) -> np.ndarray:
    """R_y(degrees) d, right-handed about +y (+z turns towards +x for positive angles)."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    d = np.asarray(d, np.float64)
    return np.stack([c * d[..., 0] + s * d[..., 2], d[..., 1], -s * d[..., 0] + c * d[..., 2]], axis=-1)


def bilinear(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The map (H, W, C) at (u, v): pixel centres at ((j + 0.5) / W, (i + 0.5) / H), wrap in u,
    clamp in v."""
    h, w = image.shape[:2]
    x = np.asarray(u, np.float64) * w - 0.5
    y = np.asarray(v, np.float64) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    j0 = np.mod(x0.astype(np.int64), w)
    j1 = np.mod(j0 + 1, w)
    i0 = np.clip(y0.astype(np.int64), 0, h - 1)
    i1 = np.clip(y0.astype(np.int64) + 1, 0, h - 1)
    img = np.asarray(image, np.float64)
    top = img[i0, j0] * (1 - fx) + img[i0, j1] * fx
    bottom = img[i1, j0] * (1 - fx) + img[i1, j1] * fx
    return top * (1 - fy) + bottom * fy


def radiance(image: np.ndarray, d: np.ndarray, scale: float = 1.0, rotation: float = 0.0) -> np.ndarray:
    """Radiance (..., 3) arriving from world directions d (..., 3)."""
    u, v = direction_to_uv(rotate_y(d, -rotation))
    return scale * bilinear(image, u, v)


def _search(cdf: np.ndarray, x: np.ndarray, row: np.ndarray | None = None) -> np.ndarray:
    """The largest index k < n with cdf[k] <= x (cdf's last axis holds n + 1 entries; `row` picks
    a row of a 2D cdf per element), by the GLSL's binary search."""
    lo = np.zeros(x.shape, np.int64)
    hi = np.full(x.shape, cdf.shape[-1] - 1, np.int64)
    while np.any(hi - lo > 1):
        mid = (lo + hi) // 2
        go = (hi - lo > 1)
        below = (cdf[mid] if row is None else cdf[row, mid]) <= x
        lo = np.where(go & below, mid, lo)
        hi = np.where(go & ~below, mid, hi)
    return lo


def sample(dist: Distribution, u1: np.ndarray, u2: np.ndarray, rotation: float = 0.0
           ) -> tuple[np.ndarray, np.ndarray]:
    """Directions (..., 3) and their solid-angle pdfs for uniform numbers u1 (row), u2 (column)."""
    h, w = dist.shape
    u1, u2 = np.asarray(u1, np.float64), np.asarray(u2, np.float64)
    m = dist.marginal.astype(np.float32).astype(np.float64)
    i = _search(m, u1)
    dv = np.clip((u1 - m[i]) / (m[i + 1] - m[i]), 0.0, 1.0)
    c = dist.conditional.astype(np.float32).astype(np.float64)
    j = _search(c, u2, row=i)
    cj, cj1 = c[i, j], c[i, j + 1]
    du = np.clip((u2 - cj) / (cj1 - cj), 0.0, 1.0)
    u, v = (j + du) / w, (i + dv) / h
    d = rotate_y(uv_to_direction(u, v), rotation)
    s = np.sin(np.pi * v)
    pdf_uv = dist.pdf_uv[i, j]
    with np.errstate(divide="ignore"):
        p = np.where(s > 0, pdf_uv / (2.0 * np.pi ** 2 * np.where(s > 0, s, 1.0)), 0.0)
    return d, p


def pdf(dist: Distribution, d: np.ndarray, rotation: float = 0.0) -> np.ndarray:
    """Solid-angle pdf of sample() producing world direction d."""
    h, w = dist.shape
    m = rotate_y(d, -rotation)
    u, v = direction_to_uv(m)
    j = np.minimum((u * w).astype(np.int64), w - 1)
    i = np.minimum((v * h).astype(np.int64), h - 1)
    y = np.clip(m[..., 1], -1, 1)
    s = np.sqrt(np.maximum((1.0 - y) * (1.0 + y), 0.0))
    with np.errstate(divide="ignore"):
        return np.where(s > 0, dist.pdf_uv[i, j] / (2.0 * np.pi ** 2 * np.where(s > 0, s, 1.0)), 0.0)
