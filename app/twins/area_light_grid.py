"""NumPy twin of glsl/lib/area_light_grid.glsl (a light's exact solid angle, the optical depth
towards its centre from the baked grid or, near the box's side towards the light, marched, and the
direct light L Omega exp(-tau)) and of its bake, glsl/area_light_transmittance.comp (one march per
texel towards the light's centre). `lights` is app/scene/area_lights.py's light_geometry tuples;
`layout` is (size, half_extent, centre, march_step): one light's block of texels over the box."""
from __future__ import annotations

import numpy as np

from radiance_probes.scene.area_lights import SPHERE
from radiance_probes.twins import area_lights
from radiance_probes.twins.medium import box_intersect, sigma_t_at, trilinear

TAU_OPAQUE = 104.0


def triangle_solid_angle(a, b, c) -> np.ndarray:
    """The solid angle of triangle a, b, c (..., 3) seen from the origin (Van Oosterom and
    Strackee)."""
    la, lb, lc = (np.linalg.norm(v, axis=-1) for v in (a, b, c))
    numerator = np.abs(np.sum(a * np.cross(b, c), axis=-1))
    denominator = (la * lb * lc + np.sum(a * b, axis=-1) * lc + np.sum(a * c, axis=-1) * lb
                   + np.sum(b * c, axis=-1) * la)
    return 2.0 * np.arctan2(numerator, denominator)


def solid_angle(light, x) -> float:
    """The exact solid angle the light fills from x: a sphere's cone, a rectangle's two triangles
    (0 from behind its emitting face)."""
    shape, c, u, v, _ = light
    x = np.asarray(x, np.float64)
    if shape == SPHERE:
        return 2.0 * np.pi * area_lights.cone(light, x)[0]
    rel = np.asarray(c, np.float64) - x
    if rel @ np.cross(u, v) >= 0:
        return 0.0
    p0, p1, p2, p3 = rel - u - v, rel + u - v, rel + u + v, rel - u + v
    return float(triangle_solid_angle(p0, p1, p2) + triangle_solid_angle(p0, p2, p3))


def march(volume, table, density_scale, x, w, t_end, n, clip=None) -> float:
    """Midpoint quadrature of sigma_t along x + t w over [0, t_end] in n points (stopping past
    tau = 104 as the GLSL does)."""
    dt = t_end / n
    tau = 0.0
    for k in range(n):
        if tau >= TAU_OPAQUE:
            break
        tau += float(sigma_t_at(volume, table, density_scale,
                                (x + (k + 0.5) * dt * w)[None], clip)[0]) * dt
    return tau


def texel_centres(layout) -> np.ndarray:
    """World positions (z, y, x, 3) of one block's texel centres."""
    size, half, centre, _ = layout
    axes = [np.asarray(centre)[i] + ((2.0 * (np.arange(size[i]) + 0.5)) / size[i] - 1.0) * half[i]
            for i in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return np.stack([x, y, z], axis=-1)


def bake(volume, table, density_scale, lights, layout, clip=None) -> np.ndarray:
    """Optical depth (light, z, y, x) at every texel centre towards each light's centre, capped at
    104 (area_light_transmittance.comp)."""
    size, half, centre, step = layout
    points = texel_centres(layout).reshape(-1, 3)
    out = np.zeros((len(lights), len(points)))
    he = np.asarray(volume.half_extent, np.float64)
    for i, light in enumerate(lights):
        for j, x in enumerate(points):
            w = np.asarray(light[1], np.float64) - x
            w = w / np.linalg.norm(w)
            t0, t1, hit = box_intersect(he, x[None], w[None], clip)
            if hit[0]:
                n = max(1, int(np.ceil((t1[0] - t0[0]) / step)))
                out[i, j] = march(volume, table, density_scale, x + t0[0] * w, w,
                                  t1[0] - t0[0], n, clip)
    return np.minimum(out, TAU_OPAQUE).reshape((len(lights), size[2], size[1], size[0]))


def lookup(depth, i, layout, x) -> float:
    """Light i's optical depth at x from its block, trilinear, clamped to the block's edge."""
    size, half, centre, _ = layout
    uvw = (np.asarray(x, np.float64) - centre) / (2.0 * np.asarray(half)) + 0.5
    return float(trilinear(depth[i], uvw * np.asarray(size, np.float64) - 0.5))


NEAR_TEXELS = 2.0   # AREA_LIGHT_NEAR_TEXELS
NEAR_POINTS = 4     # AREA_LIGHT_NEAR_POINTS


def optical_depth(volume, table, density_scale, lights, depth, layout, i, x, clip=None,
                  near_points=NEAR_POINTS) -> float:
    """area_light_optical_depth: 0 where the ray towards light i's centre misses the box; the
    first NEAR_TEXELS texels (or to the box) marched in at most near_points points, plus the
    grid's depth at the point that far along, where the box goes on beyond it (near_points 0:
    the grid's depth at x)."""
    size, half, _, step = layout
    x = np.asarray(x, np.float64)
    w = np.asarray(lights[i][1], np.float64) - x
    w = w / np.linalg.norm(w)
    t0, t1, hit = box_intersect(np.asarray(volume.half_extent, np.float64), x[None], w[None], clip)
    if not hit[0]:
        return 0.0
    texel = float(np.max(2.0 * np.asarray(half) / np.asarray(size, np.float64)))
    if near_points == 0:   # (the lab build: the grid alone)
        return lookup(depth, i, layout, x)
    t0, t1 = float(t0[0]), float(t1[0])
    t_near = min(t1, NEAR_TEXELS * texel, near_points * step)
    if not t_near > t0:
        return 0.0
    n = int(np.clip(np.ceil((t_near - t0) / step), 1, near_points))
    tau = march(volume, table, density_scale, x + t0 * w, w, t_near - t0, n, clip)
    if t1 <= t_near:
        return tau
    return tau + lookup(depth, i, layout, x + t_near * w)


def anisotropy(g: float, omega: float) -> float:
    """area_light_anisotropy: g narrowed to a cap of solid angle omega, matched at band 1."""
    return g * (1.0 - omega / (4.0 * np.pi))


def direct(volume, table, density_scale, lights, depth, layout, i, x, clip=None):
    """(L_i Omega_i(x) exp(-tau_i(x)), w_i): light i's direct light at x per unit of the kernel,
    and the unit direction to its centre."""
    x = np.asarray(x, np.float64)
    w = np.asarray(lights[i][1], np.float64) - x
    w = w / np.linalg.norm(w)
    tau = optical_depth(volume, table, density_scale, lights, depth, layout, i, x, clip)
    return np.asarray(lights[i][4], np.float64) * solid_angle(lights[i], x) * np.exp(-tau), w
