"""NumPy twin of glsl/visible_region.comp: the smallest box outside which sigma_t is 0 everywhere.

The probe grid covers only this box (app/render/probe_layout.py). The density between voxel centres
is trilinear (clamped to the edge voxel), so sigma_t can be > 0 in the cell between two layers of
voxel centres exactly when the piecewise-linear opacity is > 0 somewhere in [lo, hi], the smallest
and largest of its 8 voxels. Cells are counted with the edge voxel repeated once on each side
(n + 1 per axis), so cell k spans voxel centres k - 1 and k, and the outer cells reach the box faces.

The opacity test is exact on the table's nodes, in float32 as on the GPU: with t = d * (N - 1), the
opacity at t > 0 where t is a node with opacity > 0, or t lies inside a segment one of whose end
nodes has opacity > 0 (the interpolation of non-negative values with both weights > 0); between
lo and hi, also any node in [ceil(t_lo), floor(t_hi)] (counted from a prefix sum of positive nodes).
"""
from __future__ import annotations

import numpy as np


def positive_node_counts(table_alpha: np.ndarray) -> np.ndarray:
    """int32 (N + 1): how many nodes before index k have opacity > 0 (the shader's texture)."""
    return np.concatenate([[0], np.cumsum(np.asarray(table_alpha) > 0)]).astype(np.int32)


def opacity_positive_between(lo: np.ndarray, hi: np.ndarray, table_alpha: np.ndarray) -> np.ndarray:
    """Is the piecewise-linear opacity > 0 anywhere in [lo, hi]? (elementwise, densities in [0, 1])"""
    alpha = np.asarray(table_alpha, np.float32)
    n = len(alpha)
    positive = alpha > 0
    counts = positive_node_counts(alpha)
    last_node = np.float32(n - 1)
    t_lo = np.clip(np.asarray(lo, np.float32), 0, 1) * last_node
    t_hi = np.clip(np.asarray(hi, np.float32), 0, 1) * last_node

    def inside_positive_segment(t):
        node = np.floor(t).astype(np.int64)
        within = t != node
        nxt = np.minimum(node + 1, n - 1)
        return within & (positive[node] | positive[nxt])

    first = np.ceil(t_lo).astype(np.int64)
    last = np.floor(t_hi).astype(np.int64)
    nodes = (first <= last) & (counts[np.minimum(last + 1, n)] - counts[np.minimum(first, n)] > 0)
    return inside_positive_segment(t_lo) | inside_positive_segment(t_hi) | nodes


def visible_cells(data: np.ndarray, table_alpha: np.ndarray) -> np.ndarray:
    """bool [z, y, x], (n + 1) per axis: can sigma_t be > 0 in the cell (density scale > 0)?"""
    d = np.pad(np.asarray(data, np.float32), 1, mode="edge")
    lo = hi = None
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                s = d[dz:d.shape[0] - 1 + dz, dy:d.shape[1] - 1 + dy, dx:d.shape[2] - 1 + dx]
                lo = s if lo is None else np.minimum(lo, s)
                hi = s if hi is None else np.maximum(hi, s)
    return opacity_positive_between(lo, hi, table_alpha)


def region_from_cells(first: np.ndarray, last: np.ndarray, dims, half_extent) -> tuple[np.ndarray, np.ndarray]:
    """World (low, high) corners from the first and last visible cell per axis (x, y, z): cell k's
    low face is the box face (k = 0) or voxel centre k - 1; its high face voxel centre k or the
    box face (k = n)."""
    half = np.asarray(half_extent, np.float64)
    low, high = np.empty(3), np.empty(3)
    for axis in range(3):
        n = int(dims[axis])
        pos = np.concatenate([[-half[axis]],
                              ((np.arange(n) + 0.5) / n * 2.0 - 1.0) * half[axis], [half[axis]]])
        low[axis], high[axis] = pos[int(first[axis])], pos[int(last[axis]) + 1]
    return low, high


def visible_region(data: np.ndarray, half_extent, table_alpha: np.ndarray,
                   density_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """World-space (low, high) corners of the smallest box outside which sigma_t is 0 everywhere.
    The whole volume box when nothing is visible (then no light scatters anywhere)."""
    half = np.asarray(half_extent, np.float64)
    if density_scale <= 0:
        return -half, half
    visible = visible_cells(data, table_alpha)
    if not visible.any():
        return -half, half
    dims = np.asarray(data).shape[::-1]
    first, last = np.empty(3, np.int64), np.empty(3, np.int64)
    for axis, reduce_axes in ((0, (0, 1)), (1, (0, 2)), (2, (1, 2))):  # x, y, z
        used = np.flatnonzero(visible.any(axis=reduce_axes))
        first[axis], last[axis] = used[0], used[-1]
    return region_from_cells(first, last, dims, half)
