"""Transfer functions: a colormap preset and an opacity curve, baked into one RGBA table.

SPEC.md: ``N`` RGBA entries in [0, 1] at densities ``linspace(0, 1, N)``, linearly interpolated
between entries. The alpha column ``A(d)`` scales extinction; RGB scales the albedo.
"""
from __future__ import annotations

import json
from functools import lru_cache

import numpy as np

from .paths import ASSETS_DIR
from .scene_types import TransferFunctionSpec


@lru_cache(maxsize=1)
def _colormap_tables() -> dict[str, np.ndarray]:
    raw = json.loads((ASSETS_DIR / "colormaps.json").read_text())
    return {name: np.asarray(rows, np.float64) for name, rows in raw.items()}


COLORMAPS = ("plasma", "viridis", "inferno", "magma", "coolwarm", "turbo", "grey",
             "cool-warm", "gray", "rainbow")
ALIASES = {"cool-warm": "coolwarm", "gray": "grey", "rainbow": "turbo"}


def colormap_rgb(name: str, n: int) -> np.ndarray:
    """The preset sampled at ``n`` evenly spaced densities, shape (n, 3)."""
    name = ALIASES.get(name, name)
    table = _colormap_tables()[name]
    src = np.linspace(0.0, 1.0, len(table))
    dst = np.linspace(0.0, 1.0, n)
    return np.stack([np.interp(dst, src, table[:, c]) for c in range(3)], axis=1)


def opacity_curve(points: tuple[tuple[float, float], ...], n: int) -> np.ndarray:
    """Piecewise-linear opacity through control points, constant beyond the first and last."""
    xs = np.array([p[0] for p in points], np.float64)
    ys = np.array([p[1] for p in points], np.float64)
    return np.interp(np.linspace(0.0, 1.0, n), xs, ys)


def transfer_table(spec: TransferFunctionSpec) -> np.ndarray:
    """The RGBA table of a transfer function, float32 shape (N, 4)."""
    if spec.rgba is not None:
        table = np.asarray(spec.rgba, np.float64)
    else:
        n = spec.resolution
        table = np.concatenate([colormap_rgb(spec.colormap, n),
                                opacity_curve(spec.opacity, n)[:, None]], axis=1)
    return np.clip(table, 0.0, 1.0).astype(np.float32)


def lookup(table: np.ndarray, density: np.ndarray) -> np.ndarray:
    """NumPy twin of the GPU lookup: linear interpolation of the table at densities in [0, 1]."""
    n = len(table)
    x = np.clip(np.asarray(density, np.float64), 0.0, 1.0) * (n - 1)
    i0 = np.minimum(np.floor(x).astype(np.int64), n - 2)
    f = (x - i0)[..., None]
    a = np.asarray(table[i0], np.float64)
    # a + (b - a) f as in glsl/lib/medium.glsl: equal entries give exactly that entry.
    return a + (table[i0 + 1] - a) * f
