"""The built-in volumes, made from a size alone: the default cloud, the hydrogen-like orbital, a sphere,
shells, sheets, pinholes, specks, filaments and a head phantom (the tests' and the stress battery's
media), each a [z, y, x] float32 array of densities in [0, 1]."""
from __future__ import annotations

from typing import Callable

import numpy as np


def _grid(size: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cell-centred coordinates in [-1, 1] along each axis, broadcastable as [z, y, x]."""
    nx, ny, nz = size
    x = ((np.arange(nx) + 0.5) / nx * 2 - 1).astype(np.float32)
    y = ((np.arange(ny) + 0.5) / ny * 2 - 1).astype(np.float32)
    z = ((np.arange(nz) + 0.5) / nz * 2 - 1).astype(np.float32)
    return x[None, None, :], y[None, :, None], z[:, None, None]


def _smoothstep(e0: float, e1: float, v: np.ndarray) -> np.ndarray:
    t = np.clip((v - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def builtin_cloud(size: tuple[int, int, int]) -> np.ndarray:
    """A cumulus-like cloud: many Gaussian puffs over a flattened base, eroded by smooth noise."""
    x, y, z = _grid(size)
    rng = np.random.default_rng(7)
    shape = np.broadcast_shapes(x.shape, y.shape, z.shape)
    puffs = np.zeros(shape, np.float32)
    for _ in range(36):
        c = rng.normal(0.0, [0.3, 0.15, 0.27])
        c[1] = abs(c[1]) - 0.15  # towers rise from a common base
        r = rng.uniform(0.16, 0.34)
        puffs = np.maximum(puffs, np.exp(-(((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2)
                                           / (r * r))).astype(np.float32))
    noise = np.zeros(shape, np.float32)
    for octave in range(4):
        f = 5.0 * 2.0 ** octave
        for _ in range(3):
            k = rng.normal(size=3)
            k *= f / np.linalg.norm(k)
            noise += (np.sin(k[0] * x + k[1] * y + k[2] * z + rng.uniform(0, 2 * np.pi))
                      / (3 * 1.8 ** octave)).astype(np.float32)
    d = _smoothstep(0.3, 0.95, puffs + 0.35 * noise)
    d *= _smoothstep(0.95, 0.75, np.maximum(np.maximum(abs(x), abs(y)), abs(z)))  # zero at the box
    d *= _smoothstep(-0.45, -0.3, y)  # flat cloud base
    return (d / max(float(d.max()), 1e-6)).astype(np.float32)


def builtin_hydrogen(size: tuple[int, int, int]) -> np.ndarray:
    """Probability density of a hydrogen-like 3d_z2 orbital, |psi|^2 with psi ~ r^2 e^(-r/3)(3cos^2-1)."""
    x, y, z = _grid(size)
    s = 14.0  # Bohr radii from the centre to a face
    X, Y, Z = x * s, y * s, z * s
    r = np.sqrt(X * X + Y * Y + Z * Z) + 1e-6
    cos_t = Y / r  # orbital axis along world +y
    psi = r * r * np.exp(-r / 3.0) * (3 * cos_t * cos_t - 1)
    p = (psi * psi).astype(np.float32)
    return np.sqrt(p / p.max()).astype(np.float32)  # sqrt keeps the outer lobes visible


def builtin_sphere(size: tuple[int, int, int]) -> np.ndarray:
    """A solid ball of radius 0.6 (of the half box) with a one-voxel soft edge."""
    x, y, z = _grid(size)
    r = np.sqrt(x * x + y * y + z * z)
    edge = 2.0 / max(size)
    return (1.0 - _smoothstep(0.6 - edge, 0.6 + edge, r)).astype(np.float32)


def builtin_constant(size: tuple[int, int, int]) -> np.ndarray:
    """Density 1 everywhere: a homogeneous medium filling the box."""
    return np.ones(size[::-1], np.float32)


def builtin_empty(size: tuple[int, int, int]) -> np.ndarray:
    """Density 0 everywhere: vacuum."""
    return np.zeros(size[::-1], np.float32)


def builtin_sheet(size: tuple[int, int, int]) -> np.ndarray:
    """A thin slab one voxel thick across the middle of the box (normal along y)."""
    d = np.zeros(size[::-1], np.float32)
    d[:, size[1] // 2, :] = 1.0
    return d


def _voxel_edge(size: tuple[int, int, int]) -> float:
    """Half a voxel of the largest axis in _grid's [-1, 1] units: soft edges one voxel wide."""
    return 1.0 / max(size)


def _smooth_noise(size: tuple[int, int, int], seed: int, frequency: float,
                  octaves: int = 3) -> np.ndarray:
    """Deterministic smooth noise in about [-1, 1]: sums of random plane waves (any size)."""
    x, y, z = _grid(size)
    rng = np.random.default_rng(seed)
    shape = np.broadcast_shapes(x.shape, y.shape, z.shape)
    noise = np.zeros(shape, np.float32)
    total = 0.0
    for octave in range(octaves):
        f = frequency * 2.0 ** octave
        for _ in range(3):
            k = rng.normal(size=3)
            k *= f / np.linalg.norm(k)
            amp = 1.0 / 2.0 ** octave
            noise += amp * np.sin(k[0] * x + k[1] * y + k[2] * z
                                  + rng.uniform(0, 2 * np.pi)).astype(np.float32)
            total += amp
    return noise / (total / 2.0)


def builtin_shell(size: tuple[int, int, int]) -> np.ndarray:
    """A thin spherical shell: radius 0.6 of the half box, about two voxels thick (at least 1.5%
    of the box), density 1 in the shell and 0 inside and out."""
    x, y, z = _grid(size)
    r = np.sqrt(x * x + y * y + z * z)
    half = max(2.0 / max(size), 0.015)
    edge = _voxel_edge(size)
    inner = _smoothstep(0.6 - half - edge, 0.6 - half + edge, r)
    outer = 1.0 - _smoothstep(0.6 + half - edge, 0.6 + half + edge, r)
    return (inner * outer).astype(np.float32)


def builtin_pinholes(size: tuple[int, int, int]) -> np.ndarray:
    """A dense slab across the box (normal along y, 1/8 of the box thick, at least 2 voxels)
    pierced by a 4 x 4 grid of round holes along y, each about 1/24 of the box wide (at least
    one voxel), in a thin haze (0.02) that shows the beams the holes let through."""
    x, y, z = _grid(size)
    half_thick = max(0.125, 2.0 / size[1])
    edge = _voxel_edge(size)
    slab = (_smoothstep(-half_thick - edge, -half_thick + edge, y)
            * (1.0 - _smoothstep(half_thick - edge, half_thick + edge, y)))
    radius = max(1.0 / 12.0, 1.5 / max(size[0], size[2]))
    centres = (np.arange(4) + 0.5) / 4 * 1.6 - 0.8
    hole = np.zeros(np.broadcast_shapes(x.shape, z.shape), np.float32)
    for cx in centres:
        for cz in centres:
            d = np.sqrt((x - cx) ** 2 + (z - cz) ** 2)
            hole = np.maximum(hole, 1.0 - _smoothstep(radius - edge, radius + edge, d))
    return np.maximum(slab * (1.0 - hole), 0.02).astype(np.float32)


def builtin_speck(size: tuple[int, int, int]) -> np.ndarray:
    """A tiny dense ball (radius 3% of the half box, at least 1.5 voxels) off centre in thin
    haze: density 1 in the ball, 0.02 in the haze around it."""
    x, y, z = _grid(size)
    r = np.sqrt((x - 0.2) ** 2 + (y - 0.1) ** 2 + (z + 0.15) ** 2)
    radius = max(0.03, 3.0 / max(size))
    edge = _voxel_edge(size)
    ball = 1.0 - _smoothstep(radius - edge, radius + edge, r)
    return np.maximum(ball, 0.02).astype(np.float32)


def builtin_filaments(size: tuple[int, int, int]) -> np.ndarray:
    """Sixteen straight filaments one voxel thick along random axes through the box (each voxel
    within half a voxel of a line's axis has density 1): structure finer than any probe grid."""
    nx, ny, nz = size
    rng = np.random.default_rng(11)
    d = np.zeros((nz, ny, nx), np.float32)
    steps = 4 * max(size)
    for _ in range(16):
        start = rng.uniform(-0.8, 0.8, size=3)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        t = np.linspace(-1.6, 1.6, steps)[:, None]
        points = start + t * direction
        inside = np.all(np.abs(points) < 1.0, axis=1)
        index = np.floor((points[inside] + 1.0) / 2.0 * np.array([nx, ny, nz])).astype(int)
        index = np.clip(index, 0, np.array([nx, ny, nz]) - 1)
        d[index[:, 2], index[:, 1], index[:, 0]] = 1.0
    return d


def builtin_head(size: tuple[int, int, int]) -> np.ndarray:
    """A head-like volume: nested noisy ellipsoids, values as a CT or MRI might give them: a thin
    skin (0.3, about two voxels), fat beneath it (0.15), a skull (1.0), a noisy dense brain
    (0.55 to 0.75) and ventricles (0.1) inside it."""
    x, y, z = _grid(size)
    edge = _voxel_edge(size)
    wobble = 0.03 * _smooth_noise(size, 21, 4.0, octaves=2)

    def ellipsoid(a, b, c, cy=0.0):
        return np.sqrt((x / a) ** 2 + ((y - cy) / b) ** 2 + (z / c) ** 2) + wobble

    def inside(e, radius=1.0):
        return 1.0 - _smoothstep(radius - edge * 2, radius + edge * 2, e)

    skin_thick = max(0.02, 2.5 / max(size))
    head = ellipsoid(0.72, 0.88, 0.8)
    skull = ellipsoid(0.72 - 2 * skin_thick, 0.88 - 2 * skin_thick, 0.8 - 2 * skin_thick)
    brain = ellipsoid(0.58, 0.74, 0.66)
    ventricles = np.sqrt((np.abs(x) - 0.12) ** 2 / 0.06 ** 2 + (y - 0.05) ** 2 / 0.2 ** 2
                         + z ** 2 / 0.25 ** 2)
    texture = 0.65 + 0.1 * _smooth_noise(size, 23, 18.0)
    d = 0.3 * inside(head)                                          # skin ...
    d = np.where(inside(head, 1.0 - skin_thick / 0.8) > 0.5, 0.15, d)   # ... over fat
    d = np.maximum(d * (1.0 - inside(skull)), 0.0) + 1.0 * inside(skull)
    d = np.where(inside(brain) > 0.5, texture, d)
    d = np.where((inside(brain) > 0.5) & (ventricles < 1.0), 0.1, d)
    return np.clip(d, 0.0, 1.0).astype(np.float32)


BUILTIN_VOLUMES: dict[str, Callable[[tuple[int, int, int]], np.ndarray]] = {
    "cloud": builtin_cloud,
    "hydrogen": builtin_hydrogen,
    "sphere": builtin_sphere,
    "constant": builtin_constant,
    "empty": builtin_empty,
    "sheet": builtin_sheet,
    "shell": builtin_shell,
    "pinholes": builtin_pinholes,
    "speck": builtin_speck,
    "filaments": builtin_filaments,
    "head": builtin_head,
}
