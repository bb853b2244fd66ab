"""NumPy twin of glsl/lib/directions.glsl: the spherical Fibonacci point set and uniform random
rotations (Arvo 1992), matching the GLSL arithmetic (32-bit fixed-point golden ratio)."""
from __future__ import annotations

import numpy as np

# Golden-ratio conjugate (sqrt(5) - 1) / 2 in 32-bit fixed point: round(2^32 * 0.618033988...).
FIBONACCI_GOLDEN_FIXED = np.uint32(0x9E3779B9)


def fibonacci_direction(i, n) -> np.ndarray:
    """The i-th (0 <= i < n) of n nearly uniform unit directions; i, n broadcast, returns (..., 3).

    z = 1 - (2i + 1) / n, phi = 2 pi fract(i * (sqrt(5) - 1) / 2), the fraction taken exactly as
    the product i * 0x9E3779B9 modulo 2^32 (top 24 bits, as the GLSL converts them to float).
    0x9E3779B9 / 2^32 is 1.2e-10 below the golden-ratio conjugate: phi drifts by 7.3e-10 * i rad.
    """
    i = np.asarray(i, np.uint32)
    n = np.asarray(n, np.uint32)
    with np.errstate(over="ignore"):
        fixed = i * FIBONACCI_GOLDEN_FIXED
    fraction = (fixed >> np.uint32(8)).astype(np.float64) / 16777216.0
    phi = 2.0 * np.pi * fraction
    i64, n64 = i.astype(np.float64), n.astype(np.float64)
    z = (n64 - 2.0 * i64 - 1.0) / n64
    sin_theta = np.sqrt((2.0 * i64 + 1.0) * (2.0 * (n64 - i64) - 1.0)) / n64
    return np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), z], axis=-1)


def fibonacci_directions(n: int) -> np.ndarray:
    """All n directions of the set, (n, 3)."""
    return fibonacci_direction(np.arange(n), n)


def random_rotation(u1, u2, u3) -> np.ndarray:
    """Rotation matrices (..., 3, 3) uniform over SO(3) from uniforms in [0, 1) (Arvo 1992):
    R = -(I - 2 v v^T) R_z(2 pi u1), v = (cos(2 pi u2) sqrt(u3), sin(2 pi u2) sqrt(u3), sqrt(1 - u3)).
    """
    u1, u2, u3 = np.broadcast_arrays(*(np.asarray(u, np.float64) for u in (u1, u2, u3)))
    theta, phi = 2.0 * np.pi * u1, 2.0 * np.pi * u2
    r = np.sqrt(u3)
    v = np.stack([np.cos(phi) * r, np.sin(phi) * r, np.sqrt(np.maximum(0.0, 1.0 - u3))], axis=-1)
    c, s = np.cos(theta), np.sin(theta)
    zero, one = np.zeros_like(c), np.ones_like(c)
    rotation_z = np.stack([np.stack([c, -s, zero], -1),
                           np.stack([s, c, zero], -1),
                           np.stack([zero, zero, one], -1)], -2)
    householder = np.eye(3) - 2.0 * v[..., :, None] * v[..., None, :]
    return -householder @ rotation_z
