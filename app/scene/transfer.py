"""Transfer functions: a colormap preset and an opacity curve, baked into one RGBA table.

SPEC.md: ``N`` RGBA entries in [0, 1] at densities ``linspace(0, 1, N)``, linearly interpolated
between entries. The alpha column ``A(d)`` scales extinction; RGB scales the albedo.
"""
from __future__ import annotations

import json
from functools import lru_cache

import numpy as np

from radiance_probes.paths import ASSETS_DIR
from radiance_probes.scene.types import MAX_TRANSFER_ROWS, TransferFunctionSpec


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


def colour_points_rgb(points, n: int) -> np.ndarray:
    """Colour control points (density, r, g, b) sampled at ``n`` evenly spaced densities, linear
    between points and constant beyond the first and last, shape (n, 3)."""
    pts = np.asarray(points, np.float64).reshape(-1, 4)
    dst = np.linspace(0.0, 1.0, n)
    return np.stack([np.interp(dst, pts[:, 0], pts[:, 1 + c]) for c in range(3)], axis=1)


def transfer_rgb(spec: TransferFunctionSpec, n: int) -> np.ndarray:
    """The colours of a colormap/colour-point transfer function at ``n`` densities, (n, 3)."""
    if spec.colors is not None:
        return colour_points_rgb(spec.colors, n)
    return colormap_rgb(spec.colormap, n)


def transfer_table(spec: TransferFunctionSpec) -> np.ndarray:
    """The RGBA table of a transfer function, float32 shape (N, 4)."""
    if spec.rgba is not None:
        table = np.asarray(spec.rgba, np.float64)
    else:
        n = spec.resolution
        table = np.concatenate([transfer_rgb(spec, n),
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


# ---- the opacity curve as the editor shows it ---------------------------------------------------

MAX_EDIT_POINTS = 64


def _simplify(xs: np.ndarray, ys: np.ndarray, max_points: int) -> list[int]:
    """Indices of the points a piecewise-linear curve keeps: greedily the point farthest from the
    curve through those kept so far (Douglas-Peucker's choice, worst segment first), until every
    dropped point lies on that curve (to rounding) or max_points are kept."""
    import heapq

    def worst(a: int, b: int) -> tuple[float, int]:
        if b <= a + 1:
            return 0.0, -1
        inner = np.arange(a + 1, b)
        line = ys[a] + (ys[b] - ys[a]) * (xs[inner] - xs[a]) / (xs[b] - xs[a])
        err = np.abs(ys[inner] - line)
        k = int(np.argmax(err))
        return float(err[k]), int(inner[k])

    keep = {0, len(xs) - 1}
    heap = []
    e, k = worst(0, len(xs) - 1)
    heapq.heappush(heap, (-e, 0, len(xs) - 1, k))
    while heap and len(keep) < max_points:
        e, a, b, k = heapq.heappop(heap)
        if -e <= 1e-12:
            break
        keep.add(k)
        for lo, hi in ((a, k), (k, b)):
            e2, k2 = worst(lo, hi)
            heapq.heappush(heap, (-e2, lo, hi, k2))
    return sorted(keep)


def opacity_points(spec: TransferFunctionSpec) -> tuple[tuple[tuple[float, float], ...], float]:
    """The scene's real opacity curve as editable control points, whatever form the scene gave it
    in, and how far (in opacity) the curve through them is from it: 0 for an opacity curve; for
    explicit RGBA rows, their alpha column with the points on straight runs dropped (exact), and
    only where more than MAX_EDIT_POINTS would remain, the MAX_EDIT_POINTS that matter most."""
    if spec.rgba is None:
        return tuple(tuple(map(float, p)) for p in spec.opacity), 0.0
    alpha = np.clip(np.asarray(spec.rgba, np.float64)[:, 3], 0.0, 1.0)
    xs = np.linspace(0.0, 1.0, len(alpha))
    keep = _simplify(xs, alpha, MAX_EDIT_POINTS)
    points = tuple((float(xs[i]), float(alpha[i])) for i in keep)
    error = float(np.abs(opacity_curve(points, len(alpha)) - alpha).max())
    return points, error


def rgba_with_opacity(spec: TransferFunctionSpec, points) -> tuple[tuple[float, ...], ...]:
    """Explicit RGBA rows with their colours kept and their alpha column replaced by the curve
    through `points`. The rows are refined to at least `spec.resolution` (at most MAX_TRANSFER_ROWS) with the
    old rows among the new ones, so every old colour stays exactly where it was."""
    rows = np.asarray(spec.rgba, np.float64)
    n = len(rows)
    target = max(spec.resolution, n)
    k = max(1, -(-(target - 1) // (n - 1)))       # the fewest rows >= target with the old among them
    if (n - 1) * k + 1 > MAX_TRANSFER_ROWS:
        k = max(1, (MAX_TRANSFER_ROWS - 1) // (n - 1))
    m = (n - 1) * k + 1
    dst = np.linspace(0.0, 1.0, m)
    src = np.linspace(0.0, 1.0, n)
    rgb = np.stack([np.interp(dst, src, rows[:, c]) for c in range(3)], axis=1)
    rgb[::k] = rows[:, :3]
    alpha = opacity_curve(tuple(points), m)
    return tuple(tuple(float(v) for v in (*c, a)) for c, a in zip(rgb, alpha))
