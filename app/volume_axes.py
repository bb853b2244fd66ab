"""Which array axis is which: a file's axes (from its metadata, or the scene's volume.axes) turned
into one order, (t, c, z, y, x), or refused with a message that names the axis problem.

A file's axes come as letters of AXIS_LETTERS ("tczyx"), with "?" for an axis its metadata leaves
unnamed (tifffile's I and Q, a plain multi-page TIFF's pages). A file whose format names none
(.npy) gives None. The rules (resolve_axes):
- the scene's volume.axes, where given, must have one letter per array axis and agree with every
  axis the file names; it names the file's unnamed ones;
- without it, one unnamed axis is z where the file names no z (a plain TIFF stack's pages), a
  3D array without names is [z, y, x] (SPEC.md), and anything else is refused: reading a
  [c, z, y, x] array as 96 z-slices, as this code once did, draws a flat box a third as wide.
"""
from __future__ import annotations

import numpy as np

from .scene_flags import with_flag
from .scene_types import VolumeError

CANONICAL = "tczyx"

# tifffile's axis codes: X width, Y height, Z depth, C channel, S sample (the colours of an RGB
# page), T time; I (image sequence) and Q (unknown) are unnamed; the rest (E lambda, A angle,
# P phase, H lifetime, R tile, V, L, M) are axes a volume renderer has no place for.
TIFF_AXES = {"X": "x", "Y": "y", "Z": "z", "C": "c", "T": "t", "I": "?", "Q": "?"}
AXIS_NAMES = {"t": "time", "c": "channel", "z": "z", "y": "y", "x": "x"}


def tiff_axes(axes: str, shape: tuple[int, ...], where: str) -> str:
    """A tifffile series' axes as our letters: S (the samples of RGB pages) is the channel axis
    where the file has no C; an axis of another kind is refused unless it has one entry (dropped
    by squeeze_unit_axes)."""
    out = []
    for letter, n in zip(axes.upper(), shape):
        if letter == "S":
            if "C" in axes.upper() and n > 1:
                raise VolumeError(f"{where}: the TIFF has both channels (C) and samples per pixel "
                                  f"(S, {n}) in its axes {axes}; expected one channel axis")
            out.append("c")
        elif letter in TIFF_AXES:
            out.append(TIFF_AXES[letter])
        elif n == 1:
            out.append("1")   # a unit axis of a kind we do not use: dropped
        else:
            raise VolumeError(f"{where}: the TIFF's axis {letter} ({n} entries, in its axes "
                              f"{axes}) is neither time, channel nor space; expected axes among "
                              "T, C, Z, Y, X")
    return "".join(out)


def _describe(axes: str, shape: tuple[int, ...]) -> str:
    return "[" + ", ".join(f"{a} {n}" for a, n in zip(axes, shape)) + "]"


def resolve_axes(found: str | None, shape: tuple[int, ...], scene_axes: str | None,
                 where: str) -> str:
    """The array's axes as letters of "tczyx" (see the module's rules); raises VolumeError
    naming the axis problem."""
    ndim = len(shape)
    if scene_axes is not None:
        if len(scene_axes) != ndim:
            raise VolumeError(f"{where}: {with_flag('volume.axes')} {scene_axes!r} names "
                              f"{len(scene_axes)} axes "
                              f"but the array has {ndim} (shape {list(shape)})")
        if found is not None:
            for i, (f, s) in enumerate(zip(found, scene_axes)):
                if f not in "?1" and f != s:
                    raise VolumeError(f"{where}: {with_flag('volume.axes')} {scene_axes!r} disagrees with the "
                                      f"file's own axes {found!r} (axis {i}: the file says "
                                      f"{AXIS_NAMES[f]}, the scene {AXIS_NAMES[s]})")
        return scene_axes
    if found is None:
        if ndim == 3:
            return "zyx"
        raise VolumeError(f"{where}: a {ndim}D array (shape {list(shape)}) whose file does not say "
                          f"which axis is which; give {with_flag('volume.axes')}, e.g. \"czyx\" for channels or "
                          "\"tzyx\" for time steps")
    axes = list(found)
    unnamed = [i for i, a in enumerate(axes) if a == "?"]
    if len(unnamed) == 1 and "z" not in axes:
        axes[unnamed[0]] = "z"      # a plain stack's pages
    elif unnamed:
        raise VolumeError(f"{where}: the file leaves {len(unnamed)} of its axes unnamed "
                          f"({_describe(found, shape)}, ? unnamed); give {with_flag('volume.axes')}, e.g. "
                          "\"czyx\" or \"tzyx\", to say which is which")
    return "".join(axes)


def to_canonical(data: np.ndarray, axes: str, where: str) -> np.ndarray:
    """The array as (t, c, z, y, x), with axes of one entry where it has none; unit axes marked
    "1" dropped. A 2D (y, x) image is one z slice."""
    keep = [i for i, a in enumerate(axes) if a != "1"]
    if len(keep) != len(axes):
        data = data.reshape([data.shape[i] for i in keep])
        axes = "".join(axes[i] for i in keep)
    twice = sorted(a for a in set(axes) if axes.count(a) > 1)
    if twice:
        raise VolumeError(f"{where}: the axes {axes!r} name {AXIS_NAMES.get(twice[0], twice[0])} "
                          "twice")
    unknown = sorted(set(axes) - set(CANONICAL))
    if unknown:
        raise VolumeError(f"{where}: unknown axis {unknown[0]!r} in {axes!r}")
    missing = [a for a in "yx" if a not in axes]
    if missing:
        raise VolumeError(f"{where}: the axes {axes!r} lack {', '.join(missing)}: not a volume")
    present = [a for a in CANONICAL if a in axes]
    data = np.transpose(data, [axes.index(a) for a in present])
    sizes = dict(zip(present, data.shape))
    return data.reshape([sizes.get(a, 1) for a in CANONICAL])
