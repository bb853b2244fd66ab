"""NumPy twin of glsl/lib/light_grid.glsl (the sheared light grid's lookup, trilinear like GL's
texture filtering with clamp-to-edge) and of its bake, glsl/light_transmittance.comp (one march per
sun ray through a column of texel centres)."""
from __future__ import annotations

import numpy as np

from radiance_probes.twins.medium import sigma_t_at, trilinear
from radiance_probes.scene.light_grid_layout import LightGridLayout
from radiance_probes.io.volume import Volume


def light_grid_bake(volume: Volume, table: np.ndarray, density_scale: float, sun_direction,
                    layout: LightGridLayout, march_step: float, clip=None) -> np.ndarray:
    """Optical depth (z, y, x) at every texel centre of `layout`: each column along axis a marched
    from the box's sun side, midpoint quadrature of sigma_t over each segment between centres
    (at most march_step apart, only inside the box the layout covers), no more added once past 104
    and the texels capped there. `clip`: a crop or clip plane (app.clip_region.ClipRegion)."""
    d = np.asarray(sun_direction, np.float64)
    d = d / np.linalg.norm(d)
    a = layout.axis
    b, c = layout.ray_axes
    size = layout.size
    he = np.asarray(layout.box_half_extent, np.float64)
    centre = np.asarray(layout.centre, np.float64)
    half = np.asarray(layout.half_extent, np.float64)
    shear = np.asarray(layout.shear, np.float64)
    qb = ((2.0 * (np.arange(size[b]) + 0.5)) / size[b] - 1.0) * half[b]
    qc = ((2.0 * (np.arange(size[c]) + 0.5)) / size[c] - 1.0) * half[c]
    QB, QC = np.meshgrid(qb, qc, indexing="ij")          # rays (size[b], size[c])
    lo = np.full(QB.shape, -he[a])
    hi = np.full(QB.shape, he[a])
    for j, q in ((b, QB), (c, QC)):
        if shear[j] == 0.0:
            outside = np.abs(q) > he[j]
            lo[outside], hi[outside] = 1.0, -1.0
        else:
            s0, s1 = (-he[j] - q) / shear[j], (he[j] - q) / shear[j]
            lo = np.maximum(lo, np.minimum(s0, s1))
            hi = np.minimum(hi, np.maximum(s0, s1))
    toward_sun = 1.0 if d[a] > 0 else -1.0
    per_s = 1.0 / abs(d[a])
    centres = ((2.0 * (np.arange(size[a]) + 0.5)) / size[a] - 1.0) * he[a]
    order = range(size[a] - 1, -1, -1) if toward_sun > 0 else range(size[a])
    tau = np.zeros(QB.shape)
    out = np.zeros((size[a],) + QB.shape)
    s_from = toward_sun * he[a]
    for k in order:
        s_to = centres[k]
        s0 = np.maximum(min(s_from, s_to), lo)
        s1 = np.minimum(max(s_from, s_to), hi)
        live = (s1 > s0) & (tau < 104.0)
        if live.any():
            steps = np.maximum(1, np.ceil((s1 - s0) * per_s / march_step))
            m = np.where(live, steps, 1).astype(int)
            ds = np.where(live, (s1 - s0) / m, 0.0)
            for i in range(int(m.max())):
                step = live & (i < m)
                s = s0[step] + (i + 0.5) * ds[step]
                x = np.empty(s.shape + (3,))
                x[:, a] = s
                x[:, b] = QB[step] + shear[b] * s
                x[:, c] = QC[step] + shear[c] * s
                tau[step] += sigma_t_at(volume, table, density_scale, x + centre,
                                        clip) * ds[step] * per_s
        out[k] = np.minimum(tau, 104.0)
        s_from = s_to
    # out is (a, b, c); return (z, y, x)
    axes_xyz = np.argsort([a, b, c])          # position of x, y, z in (a, b, c)
    return np.transpose(out, axes_xyz[::-1])


def light_grid_lookup(optical_depth: np.ndarray, layout: LightGridLayout, points) -> np.ndarray:
    """Optical depth at world points (..., 3) from the grid (z, y, x), as light_grid.glsl reads
    it: sheared coordinates, then trilinear filtering of texel centres, clamped to the edge."""
    pts = np.asarray(points, np.float64) - np.asarray(layout.centre, np.float64)
    q = pts - np.asarray(layout.shear) * pts[..., layout.axis:layout.axis + 1]
    uvw = q / (2.0 * np.asarray(layout.half_extent)) + 0.5
    return trilinear(optical_depth, uvw * np.asarray(layout.size, np.float64) - 0.5)


def light_grid_optical_depth(optical_depth: np.ndarray, layout: LightGridLayout, volume: Volume,
                             table: np.ndarray, density_scale: float, sun_direction, points,
                             texel: float, march_step: float) -> np.ndarray:
    """lib/light_grid.glsl light_grid_optical_depth (LIGHT_GRID_FACE_MARCH 1) at world points
    (..., 3): 0 where the sun's ray from the point does not cross the box; within one texel
    (`texel`, LightTransmittance.uniforms' light_grid_texel) of where it leaves the box, the
    midpoint march of sigma_t to the box (at most 8 points of about march_step); elsewhere the
    grid's lookup."""
    from radiance_probes.twins.medium import box_intersect
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    d = np.asarray(sun_direction, np.float64)
    d = d / np.linalg.norm(d)
    t0, t1, hit = box_intersect(volume.half_extent, pts, np.broadcast_to(d, pts.shape))
    tau = light_grid_lookup(optical_depth, layout, pts)
    near = hit & (t1 < texel)
    for i in np.flatnonzero(near):
        n = int(np.clip(np.ceil((t1[i] - t0[i]) / march_step), 1, 8))
        dt = (t1[i] - t0[i]) / n
        ts = t0[i] + (np.arange(n) + 0.5) * dt
        tau[i] = np.sum(sigma_t_at(volume, table, density_scale, pts[i] + ts[:, None] * d)) * dt
    tau[~hit] = 0.0
    return tau.reshape(np.shape(points)[:-1])
