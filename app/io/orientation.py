"""Anatomical orientation (docs/scene-format.md, "Orientation"): a volume whose file says where
its axes point in the patient is shown with world +x = the patient's left, +y = superior and
+z = anterior (scene key ``"orientation": "patient"``), by permuting and flipping the array's axes,
never resampling; what is left over (an oblique acquisition) stays metadata and is named in a note.

Directions are 3x3 matrices whose columns are the unit directions, in the patient's LPS frame
(DICOM's: +x left, +y posterior, +z superior), of the array's axes x, y, z (``data[z, y, x]``)
pointing towards increasing index. NIfTI (RAS) and NRRD (its `space`) are converted into LPS.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

# The patient directions world +x, +y, +z stand for, in LPS: left, superior, anterior.
PATIENT_WORLD = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]).T
# A residual rotation smaller than this (degrees) is rounding in the headers, not an oblique scan.
OBLIQUE_DEGREES = 0.5
# RAS-type spaces of NRRD and NIfTI, as sign flips into LPS.
RAS_TO_LPS = np.diag([-1.0, -1.0, 1.0])
NRRD_SPACES = {
    "left-posterior-superior": (1, 1, 1), "lps": (1, 1, 1),
    "right-anterior-superior": (-1, -1, 1), "ras": (-1, -1, 1),
    "left-anterior-superior": (1, -1, 1), "las": (1, -1, 1),
}
_LETTERS = {(0, 1): "L", (0, -1): "R", (1, 1): "P", (1, -1): "A", (2, 1): "S", (2, -1): "I"}


@dataclass(frozen=True)
class Reoriented:
    data: np.ndarray                      # [z, y, x], a view or copy of the input, not resampled
    spacing: tuple[float, float, float]
    direction: np.ndarray                 # the new axes' LPS directions (columns)
    axes: tuple[int, int, int]            # world axis w shows the input's array axis axes[w]
    flips: tuple[bool, bool, bool]        # ... reversed where True
    oblique_degrees: float                # the residual rotation's angle (0: none)


def unit_columns(matrix: np.ndarray) -> np.ndarray | None:
    """The matrix's columns scaled to unit length, or None where one is zero or not finite."""
    m = np.asarray(matrix, np.float64)
    if m.shape != (3, 3) or not np.isfinite(m).all():
        return None
    norms = np.linalg.norm(m, axis=0)
    if not (norms > 1e-12).all():
        return None
    return m / norms


def patient_axes(direction: np.ndarray) -> str:
    """Each array axis's nearest patient direction, e.g. "x: L, y: P, z: S" (towards increasing
    index)."""
    out = []
    for name, column in zip("xyz", np.asarray(direction).T):
        k = int(np.argmax(np.abs(column)))
        out.append(f"{name}: {_LETTERS[(k, 1 if column[k] > 0 else -1)]}")
    return ", ".join(out)


def residual_degrees(direction: np.ndarray) -> float:
    """The angle of the rotation between the axes' directions and world's patient axes."""
    r = PATIENT_WORLD.T @ np.asarray(direction, np.float64)
    u, _, vt = np.linalg.svd(r)          # the nearest rotation, where shear left it not quite one
    r = u @ vt
    return math.degrees(math.acos(float(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))))


def to_patient(data_zyx: np.ndarray, spacing: tuple[float, float, float],
               direction: np.ndarray) -> Reoriented:
    """The axis order and flips that bring the array's axes closest to world +x = left,
    +y = superior, +z = anterior (the permutation maximising the summed alignment), applied."""
    d = np.asarray(direction, np.float64)
    align = PATIENT_WORLD.T @ d            # [world axis, array axis]: cosines
    best = max(itertools.permutations(range(3)),
               key=lambda p: sum(abs(align[w, p[w]]) for w in range(3)))
    flips = tuple(bool(align[w, best[w]] < 0) for w in range(3))
    # numpy axis of array axis a is 2 - a; world axis w becomes numpy axis 2 - w
    out = np.transpose(data_zyx, (2 - best[2], 2 - best[1], 2 - best[0]))
    for w in range(3):
        if flips[w]:
            out = np.flip(out, axis=2 - w)
    new_direction = np.stack([d[:, best[w]] * (-1.0 if flips[w] else 1.0) for w in range(3)],
                             axis=1)
    angle = residual_degrees(new_direction)
    return Reoriented(np.ascontiguousarray(out), tuple(float(spacing[best[w]]) for w in range(3)),
                      new_direction, tuple(best), flips,
                      angle if angle >= OBLIQUE_DEGREES else 0.0)
