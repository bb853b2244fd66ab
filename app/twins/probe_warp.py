"""NumPy twin of glsl/lib/probe_warp.glsl: an adaptive probe layout's warp from world fractions of
the probe box to the probe textures' coordinates, its table, and the probes' positions.

Along each axis the probe planes sit at world fractions `planes` (increasing, in (0, 1)); plane i
keeps texture coordinate (i + 0.5) / n. The warp is piecewise linear through the knots (0, 0),
(planes[i], (i + 0.5) / n) and (1, 1); with planes[i] = (i + 0.5) / n it is the identity.
"""
from __future__ import annotations

import numpy as np

# Columns of the warp table (and at least the most probes per axis, whose planes share it).
WARP_COLUMNS = 16384   # GL 4.3 guarantees 2D textures this wide
WARP_ROWS = 6    # rows 0..2: the warp per axis; rows 3..5: the planes per axis


def uniform_planes(n: int) -> np.ndarray:
    """World fractions of n evenly spaced probe planes: (i + 0.5) / n."""
    return (np.arange(n, dtype=np.float64) + 0.5) / n


def warp_knots(planes) -> tuple[np.ndarray, np.ndarray]:
    """The warp's knots: world fractions and their texture coordinates."""
    p = np.asarray(planes, np.float64)
    n = len(p)
    return (np.concatenate([[0.0], p, [1.0]]),
            np.concatenate([[0.0], (np.arange(n) + 0.5) / n, [1.0]]))


def warp_exact(planes, s) -> np.ndarray:
    """The warp at world fractions s (clamped to [0, 1]), from its knots in float64."""
    knots_s, knots_u = warp_knots(planes)
    return np.interp(np.clip(np.asarray(s, np.float64), 0.0, 1.0), knots_s, knots_u)


def warp_table(planes: tuple, columns: int = WARP_COLUMNS) -> np.ndarray:
    """float32 (WARP_ROWS, columns): row a the warp of axis a at s = j / (columns - 1); row 3 + a
    the planes of axis a from column 0 (the rest 0). What the probe_warp texture holds."""
    table = np.zeros((WARP_ROWS, columns), np.float32)
    s = np.arange(columns, dtype=np.float64) / (columns - 1)
    for axis, p in enumerate(planes):
        if len(p) > columns:
            raise ValueError(f"{len(p)} probe planes on axis {axis}: at most {columns}")
        table[axis] = warp_exact(p, s)
        table[3 + axis, :len(p)] = p
    return table


def warp_lookup(table: np.ndarray, s) -> np.ndarray:
    """probe_warp_uvw: texture coordinates (..., 3) at world fractions s (..., 3), the table read
    as GL's linear filter reads it (float weights, as llvmpipe; GPUs may round them to 8 bits)."""
    s = np.clip(np.asarray(s, np.float64), 0.0, 1.0)
    columns = table.shape[1]
    out = np.empty(s.shape, np.float64)
    for axis in range(3):
        coord = ((s[..., axis] * (columns - 1) + 0.5) / columns) * columns - 0.5
        j = np.clip(np.floor(coord).astype(np.int64), 0, columns - 1)
        f = coord - j
        j1 = np.minimum(j + 1, columns - 1)
        row = table[axis].astype(np.float64)
        out[..., axis] = row[j] * (1.0 - f) + row[j1] * f
    return out


def probe_fractions(grid: tuple[int, int, int], planes: tuple | None) -> np.ndarray:
    """World fractions (count, 3) of the probes in index order i + nx (j + ny k): planes[a] per
    axis, or evenly spaced where `planes` is None (probe_position in lib/probes.glsl)."""
    nx, ny, nz = grid
    if planes is None:
        planes = tuple(uniform_planes(n) for n in grid)
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    px, py, pz = (np.asarray(p, np.float64) for p in planes)
    return np.stack([px[i], py[j], pz[k]], axis=-1).reshape(-1, 3)


def texture_trilinear(values: np.ndarray, uvw: np.ndarray) -> np.ndarray:
    """GL's linear filter of a 3D texture (values (nz, ny, nx), texel centres at (i + 0.5) / n,
    clamped to the edge) at coordinates uvw (..., 3): how probe_fetch blends the probes."""
    uvw = np.asarray(uvw, np.float64)
    nz, ny, nx = values.shape
    out = np.zeros(uvw.shape[:-1])
    base, frac = [], []
    for axis, n in enumerate((nx, ny, nz)):
        c = uvw[..., axis] * n - 0.5
        b = np.floor(c)
        base.append(b.astype(np.int64))
        frac.append(c - b)
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                ix = np.clip(base[0] + dx, 0, nx - 1)
                iy = np.clip(base[1] + dy, 0, ny - 1)
                iz = np.clip(base[2] + dz, 0, nz - 1)
                w = ((frac[0] if dx else 1 - frac[0]) * (frac[1] if dy else 1 - frac[1])
                     * (frac[2] if dz else 1 - frac[2]))
                out += w * values[iz, iy, ix]
    return out


def interpolate_between_planes(values: np.ndarray, planes: tuple, s: np.ndarray) -> np.ndarray:
    """Trilinear interpolation between the 8 probes around world fractions s (..., 3) at their
    real positions (planes per axis), the outer probes' values beyond them: what the warp makes
    texture_trilinear at probe_warp_uvw compute, up to the table's error."""
    uvw = np.stack([warp_exact(planes[a], np.asarray(s)[..., a]) for a in range(3)], axis=-1)
    return texture_trilinear(values, uvw)
