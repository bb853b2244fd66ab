"""NumPy references for the transport tests: transmittance and single scattering by quadrature,
averaged over each pixel's area as SPEC.md's box filter says."""
from __future__ import annotations

import numpy as np

from radiance_probes.twins.camera import camera_frame
from radiance_probes.twins.medium import box_intersect, sigma_t_at
from radiance_probes.twins.phase import phase_hg
from radiance_probes.io.scene_file import Scene
from radiance_probes.scene.transfer import transfer_table
from radiance_probes.io.volume import Volume


def pixel_rays(scene: Scene, sub: int):
    """Ray directions at sub x sub stratified points in every pixel: (H, W, sub*sub, 3)."""
    cam = camera_frame(scene.camera)
    offs = (np.arange(sub) + 0.5) / sub
    ox, oy = np.meshgrid(offs, offs)
    cols = np.arange(cam.width)[None, :, None] + ox.ravel()[None, None, :]
    rows = np.arange(cam.height)[:, None, None] + oy.ravel()[None, None, :]
    cols, rows = np.broadcast_arrays(cols, rows)
    return cam, cam.ray_directions(cols.astype(np.float64), rows.astype(np.float64))


def optical_depth(volume: Volume, table, density_scale, origins, directions, t0, t1, steps):
    """Midpoint-rule integral of sigma_t along each ray segment; arrays broadcast over rays."""
    u = (np.arange(steps) + 0.5) / steps
    t = t0[..., None] + (t1 - t0)[..., None] * u
    pts = origins[..., None, :] + t[..., None] * directions[..., None, :]
    sig = sigma_t_at(volume, table, density_scale, pts)
    return sig.mean(axis=-1) * np.maximum(t1 - t0, 0.0)


def transmittance_image(scene: Scene, volume: Volume, sub: int = 4, steps: int = 256) -> np.ndarray:
    """Per-pixel mean of exp(-optical depth) through the box: the image of a pure absorber (env 1)."""
    cam, dirs = pixel_rays(scene, sub)
    table = transfer_table(scene.transfer_function)
    he = volume.half_extent.astype(np.float64)
    eye = np.broadcast_to(cam.eye.astype(np.float64), dirs.shape)
    t0, t1, hit = box_intersect(he, eye, dirs)
    tau = optical_depth(volume, table, scene.density_scale, eye, dirs, t0, np.where(hit, t1, t0), steps)
    return np.exp(-tau).mean(axis=-1)


def single_scatter_image(scene: Scene, volume: Volume, sub: int = 3, steps: int = 128,
                         shadow_steps: int = 48) -> np.ndarray:
    """Per-pixel single-scattered sun radiance (RGB) by nested quadrature; no environment."""
    cam, dirs = pixel_rays(scene, sub)
    table = transfer_table(scene.transfer_function)
    he = volume.half_extent.astype(np.float64)
    eye = np.broadcast_to(cam.eye.astype(np.float64), dirs.shape)
    t0, t1, hit = box_intersect(he, eye, dirs)
    t1 = np.where(hit, t1, t0)
    sun = np.asarray(scene.light.direction, np.float64)
    E = np.asarray(scene.light.irradiance, np.float64)
    u = (np.arange(steps) + 0.5) / steps
    dt = (t1 - t0) / steps
    out = np.zeros(dirs.shape[:-1] + (3,))
    tau_cam = np.zeros(dirs.shape[:-1])
    from radiance_probes.twins.medium import albedo_at
    for k in range(steps):
        t = t0 + (t1 - t0) * u[k]
        x = eye + t[..., None] * dirs
        sig = sigma_t_at(volume, table, scene.density_scale, x)
        tau_mid = tau_cam + 0.5 * sig * dt  # optical depth from the entry to x (midpoint rule)
        s0, s1, _ = box_intersect(he, x, np.broadcast_to(sun, x.shape))
        tau_sun = optical_depth(volume, table, scene.density_scale, x, np.broadcast_to(sun, x.shape),
                                np.zeros_like(s1), s1, shadow_steps)
        alb = albedo_at(volume, table, scene.albedo, x)
        ph = phase_hg(dirs @ sun, scene.anisotropy)
        w = (np.exp(-tau_mid - tau_sun) * sig * ph * dt)[..., None]
        out += w * alb * E
        tau_cam += sig * dt
    return out.mean(axis=-2)
