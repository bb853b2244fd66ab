"""NumPy twin of glsl/lib/denoise_guides.glsl and glsl/denoise_guide_images.comp: the denoiser's albedo
and normal guides of one jittered frame (the raymarcher's rays and segments)."""
from __future__ import annotations

import numpy as np

from radiance_probes.twins.camera import CameraFrame
from radiance_probes.twins.medium import box_intersect, classified_at
from radiance_probes.twins.rng import rng_next, rng_seed

GUIDE_GRADIENT_WEIGHT = 1e-4


def _sigma_t(volume, table, density_scale, points, clip):
    return density_scale * classified_at(volume, table, points, clip)[..., 3]


def normal_at(volume, table, density_scale: float, points: np.ndarray, h: float,
              clip=None) -> np.ndarray:
    """-grad sigma_t / |grad sigma_t| by central differences at +-h per axis; 0 where flat."""
    grad = np.stack([_sigma_t(volume, table, density_scale, points + h * e, clip)
                     - _sigma_t(volume, table, density_scale, points - h * e, clip)
                     for e in np.eye(3)], axis=-1)
    length = np.linalg.norm(grad, axis=-1, keepdims=True)
    return np.where(length > 0, -grad / np.where(length > 0, length, 1.0), 0.0)


def guide_march(volume, table, density_scale: float, albedo: float, origin: np.ndarray,
                directions: np.ndarray, jitter: np.ndarray, step: float, gradient_step: float,
                clip=None) -> tuple[np.ndarray, np.ndarray]:
    """The albedo and normal guides of rays (N, 3) from `origin`, each with its jitter (N,)."""
    origin = np.asarray(origin, np.float64)
    d = np.asarray(directions, np.float64)
    t0, t1, hit = box_intersect(volume.half_extent, origin[None, :], d, clip)
    n = np.clip(np.ceil(np.where(hit, (t1 - t0) / step, 1.0)), 1, 8192).astype(int)
    dt = np.where(hit, (t1 - t0) / n, 0.0)
    transmittance = np.where(hit, 1.0, 0.0)   # a miss: all weight to the background below
    albedo_guide = np.zeros(d.shape)
    normal_guide = np.zeros(d.shape)
    for i in range(int(n.max()) if hit.any() else 0):
        live = hit & (i < n) & (transmittance > 1e-6)
        if not live.any():
            break
        x = origin + (t0 + (i + jitter) * dt)[:, None] * d
        tf = classified_at(volume, table, x[live], clip)
        sigma_t = density_scale * tf[:, 3]
        opacity = np.where(sigma_t > 0, 1.0 - np.exp(-sigma_t * dt[live]), 0.0)
        w = transmittance[live] * opacity
        albedo_guide[live] += w[:, None] * albedo * tf[:, :3]
        strong = w > GUIDE_GRADIENT_WEIGHT
        if strong.any():
            idx = np.flatnonzero(live)[strong]
            normal_guide[idx] += w[strong, None] * normal_at(volume, table, density_scale,
                                                             x[idx], gradient_step, clip)
        transmittance[live] *= 1.0 - opacity
    albedo_guide += np.where(hit, transmittance, 1.0)[:, None]
    return albedo_guide, normal_guide


def guide_frame(volume, table, density_scale: float, albedo: float, camera: CameraFrame,
                step: float, gradient_step: float, frame: int = 0, seed: int = 0,
                clip=None) -> tuple[np.ndarray, np.ndarray]:
    """One frame of denoise_guide_images.comp: (albedo, normal) images (H, W, 3)."""
    w, h = camera.width, camera.height
    py, px = np.mgrid[0:h, 0:w]
    rng = rng_seed((py * w + px).ravel(), frame, seed)
    rng, sx = rng_next(rng)
    rng, sy = rng_next(rng)
    rng, jitter = rng_next(rng)
    dirs = camera.ray_directions(px.ravel() + sx.astype(np.float64),
                                 py.ravel() + sy.astype(np.float64))
    a, nrm = guide_march(volume, table, density_scale, albedo, camera.eye, dirs,
                         jitter.astype(np.float64), step, gradient_step, clip)
    return a.reshape(h, w, 3), nrm.reshape(h, w, 3)
