"""Area lights on the host: a scene's lights checked against the volume box (each must lie wholly
outside it: the path tracer meets a light only after a ray leaves the box, or before a camera ray
enters it) and turned into glsl/lib/area_lights.glsl's uniforms. Their sampling and pdfs' twin:
app/twins/area_lights.py.

A rectangle's edges lie along the orthonormal basis of its normal (app/scene/basis.py, Duff et al.
2017): width along the first vector, height along the second. It
emits from its front face (the side its normal points to) only."""
from __future__ import annotations

import numpy as np

from radiance_probes.scene.types import MAX_AREA_LIGHTS, SceneError
from radiance_probes.scene.basis import orthonormal_basis

SPHERE, RECTANGLE = 0, 1


def enabled_lights(scene) -> list:
    return [light for light in scene.area_lights if light.enabled]


def light_geometry(light) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(shape, centre, u, v, radiance): a sphere's u = (radius, 0, 0), v = 0; a rectangle's u and v
    its half edges (world), its normal u x v / |u x v|."""
    centre = np.asarray(light.position, np.float64)
    radiance = np.asarray(light.colour, np.float64) * float(light.strength)
    if light.shape == "sphere":
        return SPHERE, centre, np.array([float(light.size), 0.0, 0.0]), np.zeros(3), radiance
    n = np.asarray(light.normal, np.float64)
    n = n / np.linalg.norm(n)
    b1, b2 = orthonormal_basis(n)
    w, h = (float(v) for v in light.size)
    return RECTANGLE, centre, 0.5 * w * b1, 0.5 * h * b2, radiance


def _rectangle_meets_box(centre, u, v, half) -> bool:
    """Whether the rectangle centre + s u + t v (|s|, |t| <= 1) meets the box |x| <= half
    (separating axis test: the box's axes, the rectangle's normal, and their edges' crosses)."""
    axes = [np.eye(3)[i] for i in range(3)] + [np.cross(u, v)]
    axes += [np.cross(e, np.eye(3)[i]) for e in (u, v) for i in range(3)]
    for a in axes:
        if np.linalg.norm(a) < 1e-12:
            continue
        r_box = float(np.abs(a) @ half)
        r_rect = abs(float(a @ u)) + abs(float(a @ v))
        if abs(float(a @ centre)) > r_box + r_rect:
            return False
    return True


def check_area_lights(scene, half_extent) -> None:
    """Raises SceneError naming the light that reaches into the volume box of `half_extent`."""
    half = np.asarray(half_extent, np.float64)
    for i, light in enumerate(scene.area_lights):
        shape, centre, u, v, _ = light_geometry(light)
        if shape == SPHERE:
            nearest = np.clip(centre, -half, half)
            inside = np.linalg.norm(centre - nearest) <= u[0]
        else:
            inside = _rectangle_meets_box(centre, u, v, half)
        if inside:
            box = " x ".join(f"{2 * h:.4g}" for h in half)
            raise SceneError(f"area_lights[{i}]: the {light.shape} light at "
                             f"{list(light.position)} reaches into the volume box ({box} world "
                             "units centred at the origin); lights must lie outside it")


def area_light_uniforms(scene) -> dict:
    """glsl/lib/area_lights.glsl's uniforms for the scene's enabled lights (arrays padded to
    MAX_AREA_LIGHTS)."""
    lights = enabled_lights(scene)
    shapes, positions, us, vs, radiances = [], [], [], [], []
    for light in lights:
        shape, centre, u, v, radiance = light_geometry(light)
        shapes.append(shape)
        positions.append(tuple(centre))
        us.append(tuple(u))
        vs.append(tuple(v))
        radiances.append(tuple(radiance))
    pad = MAX_AREA_LIGHTS - len(lights)
    zero = (0.0, 0.0, 0.0)
    return {"area_light_count": len(lights), "area_light_shape": shapes + [0] * pad,
            "area_light_position": positions + [zero] * pad, "area_light_u": us + [zero] * pad,
            "area_light_v": vs + [zero] * pad, "area_light_radiance": radiances + [zero] * pad}
