"""NumPy twin of glsl/lib/area_lights.glsl: a light's distance along a ray, the first light a ray
meets, what it emits, a direction's pdf and the sampler. `lights` is the list of
app/scene/area_lights.py light_geometry tuples (shape, centre, u, v, radiance); x and w are (3,)."""
from __future__ import annotations

import numpy as np

from radiance_probes.scene.area_lights import SPHERE
from radiance_probes.twins.phase import orthonormal_basis


def distance(light, x, w) -> float:
    shape, c, u, v, _ = light
    x, w = np.asarray(x, np.float64), np.asarray(w, np.float64)
    if shape == SPHERE:
        r = u[0]
        oc = x - c
        b = oc @ w
        perp = oc - b * w
        disc = r * r - perp @ perp
        if disc < 0:
            return -1.0
        t = -b - np.sqrt(disc)
        return float(t) if t > 0 else -1.0
    n = np.cross(u, v)
    denom = w @ n
    if denom == 0:
        return -1.0
    t = ((c - x) @ n) / denom
    if not t > 0:
        return -1.0
    q = x + t * w - c
    s, r = q @ u / (u @ u), q @ v / (v @ v)
    return float(t) if abs(s) <= 1 and abs(r) <= 1 else -1.0


def first_hit(lights, x, w) -> tuple[int, float]:
    hit, best = -1, np.inf
    for i, light in enumerate(lights):
        t = distance(light, x, w)
        if 0 < t < best:
            hit, best = i, t
    return hit, best


def emitted(light, w) -> np.ndarray:
    shape, _, u, v, radiance = light
    if shape != SPHERE and np.asarray(w) @ np.cross(u, v) >= 0:
        return np.zeros(3)
    return np.asarray(radiance, np.float64)


def cone(light, x) -> tuple[float, np.ndarray, float]:
    """(1 - cos theta_max, the axis, cos theta_max) of a sphere light seen from x."""
    _, c, u, _, _ = light
    d = c - np.asarray(x, np.float64)
    dist2 = d @ d
    sin2 = min(u[0] ** 2 / dist2, 1.0)
    cos_max = np.sqrt(max(1 - sin2, 0.0))
    return sin2 / (1 + cos_max), d / np.sqrt(dist2), cos_max


def pdf(lights, i, x, w, t) -> float:
    shape, _, u, v, _ = lights[i]
    if shape == SPHERE:
        value = 1.0 / (2 * np.pi * cone(lights[i], x)[0])
    else:
        n = np.cross(u, v)
        area4 = np.linalg.norm(n)
        cos_light = abs(np.asarray(w) @ n) / area4
        value = t * t / (4 * area4 * cos_light) if cos_light > 0 else 0.0
    return value / len(lights)


def direction_pdf(lights, x, w) -> float:
    """The sampler's pdf of w: that of the first light w meets (0 where it meets none)."""
    i, t = first_hit(lights, x, w)
    return 0.0 if i < 0 else pdf(lights, i, x, w, t)


def sample(lights, x, u0, u1, u2) -> tuple[np.ndarray, np.ndarray, float]:
    """(w, radiance, pdf) as area_light_sample draws them from uniform numbers u0, u1, u2."""
    x = np.asarray(x, np.float64)
    i = min(int(u0 * len(lights)), len(lights) - 1)
    shape, c, u, v, _ = lights[i]
    if shape == SPHERE:
        one_minus_cos, axis, _ = cone(lights[i], x)
        a = u1 * one_minus_cos
        cos_t, sin_t = 1 - a, np.sqrt(max(a * (2 - a), 0.0))
        phi = 2 * np.pi * u2
        b1, b2 = orthonormal_basis(axis)
        w = sin_t * (np.cos(phi) * b1 + np.sin(phi) * b2) + cos_t * axis
    else:
        w = c + (2 * u1 - 1) * u + (2 * u2 - 1) * v - x
    w = w / np.linalg.norm(w)
    hit, t = first_hit(lights, x, w)
    if hit != i:
        return w, np.zeros(3), 0.0
    return w, emitted(lights[i], w), pdf(lights, i, x, w, t)
