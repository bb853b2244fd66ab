"""NumPy twin of glsl/visible_region.comp: the smallest box outside which sigma_t is 0 everywhere.

The probe grid covers only this box (app/rendering/probes/layout.py). The density between voxel centres
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


def visible_cells(data: np.ndarray, table_alpha, clip=None,
                  half_extent=None) -> np.ndarray:
    """bool [z, y, x], (n + 1) per axis: can sigma_t be > 0 in the cell (density scale > 0)?
    With a crop or clip plane (`clip`, an app.clip_region.ClipRegion in the box of `half_extent`):
    over the kept voxels alone, (count + 1) per axis, and False where the plane cuts a cell away.
    Several channels (data [z, y, x, c], `table_alpha` an app.channels.ChannelTables): where
    any channel switched on is visible."""
    if hasattr(table_alpha, "tables"):
        out = None
        for c, (table, on) in enumerate(zip(table_alpha.tables, table_alpha.on)):
            if on:
                v = visible_cells(np.asarray(data)[..., c], table[:, 3], clip, half_extent)
                out = v if out is None else out | v
        return out
    data = np.asarray(data, np.float32)
    if clip is not None:
        (fx, fy, fz), (nx, ny, nz) = clip.voxel_first, clip.voxel_count
        data = data[fz:fz + nz, fy:fy + ny, fx:fx + nx]
    d = np.pad(data, 1, mode="edge")
    lo = hi = None
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                s = d[dz:d.shape[0] - 1 + dz, dy:d.shape[1] - 1 + dy, dx:d.shape[2] - 1 + dx]
                lo = s if lo is None else np.minimum(lo, s)
                hi = s if hi is None else np.maximum(hi, s)
    visible = opacity_positive_between(lo, hi, table_alpha)
    if clip is not None:
        visible &= ~_cells_cut_away(clip, half_extent, np.asarray(data.shape[::-1]) + 1)
    return visible


def _cell_faces(clip, half_extent, axis: int) -> np.ndarray:
    """World positions of the kept cells' faces along an axis: the kept box's low face, the kept
    voxels' centres, its high face (count + 2 values; cell k spans faces k and k + 1)."""
    half = np.asarray(half_extent, np.float32).astype(np.float64)
    first, count = clip.voxel_first[axis], clip.voxel_count[axis]
    n = clip.dims[axis]
    centres = ((2.0 * (first + np.arange(count) + 0.5)) / n - 1.0) * half[axis]
    return np.concatenate([[clip.box_min[axis]], centres, [clip.box_max[axis]]])


def _cells_cut_away(clip, half_extent, cells) -> np.ndarray:
    faces = [_cell_faces(clip, half_extent, a) for a in range(3)]
    half = np.asarray(half_extent, np.float32).astype(np.float64)
    slack = half / np.asarray(clip.dims) / 64.0
    k, j, i = np.meshgrid(*(np.arange(c) for c in cells[::-1]), indexing="ij")
    lo = np.stack([faces[0][i], faces[1][j], faces[2][k]], -1)
    hi = np.stack([faces[0][i + 1], faces[1][j + 1], faces[2][k + 1]], -1)
    return clip.cuts_box(lo - slack, hi + slack)


def region_from_cells(first: np.ndarray, last: np.ndarray, dims, half_extent,
                      clip=None) -> tuple[np.ndarray, np.ndarray]:
    """World (low, high) corners from the first and last visible cell per axis (x, y, z): cell k's
    low face is the box face (k = 0) or voxel centre k - 1; its high face voxel centre k or the
    box face (k = n). With a crop (`clip`), cells count over the kept voxels and the box is the
    kept box."""
    half = np.asarray(half_extent, np.float64)
    low, high = np.empty(3), np.empty(3)
    for axis in range(3):
        n = int(dims[axis])
        if clip is None:
            pos = np.concatenate([[-half[axis]], ((np.arange(n) + 0.5) / n * 2.0 - 1.0) * half[axis],
                                  [half[axis]]])
        else:
            v0, count = clip.voxel_first[axis], clip.voxel_count[axis]
            pos = np.concatenate([[clip.box_min[axis]],
                                  ((v0 + np.arange(count) + 0.5) / n * 2.0 - 1.0) * half[axis],
                                  [clip.box_max[axis]]])
        low[axis], high[axis] = pos[int(first[axis])], pos[int(last[axis]) + 1]
    return low, high


def visible_region(data: np.ndarray, half_extent, table_alpha,
                   density_scale: float, clip=None) -> tuple[np.ndarray, np.ndarray]:
    """World-space (low, high) corners of the smallest box outside which sigma_t is 0 everywhere.
    The whole volume box (the kept box with a crop or clip plane) when nothing is visible (then
    no light scatters anywhere)."""
    half = np.asarray(half_extent, np.float64)
    whole = ((-half, half) if clip is None else
             (np.asarray(clip.box_min, np.float64), np.asarray(clip.box_max, np.float64)))
    if density_scale <= 0 or (clip is not None and clip.empty):
        return whole
    visible = visible_cells(data, table_alpha, clip, half_extent)
    if not visible.any():
        return whole
    dims = np.asarray(data).shape[:3][::-1]
    first, last = np.empty(3, np.int64), np.empty(3, np.int64)
    for axis, reduce_axes in ((0, (0, 1)), (1, (0, 2)), (2, (1, 2))):  # x, y, z
        used = np.flatnonzero(visible.any(axis=reduce_axes))
        first[axis], last[axis] = used[0], used[-1]
    return region_from_cells(first, last, dims, half, clip)
