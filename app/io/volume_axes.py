"""Which array axis is which: a file's axes (from its metadata, or the scene's volume.axes) turned
into one order, (t, c, z, y, x), or refused with a message that names the axis problem.

A file's axes come as letters of AXIS_LETTERS ("tczyx"), with "?" for an axis its metadata leaves
unnamed (tifffile's I and Q, a plain multi-page TIFF's pages). A file whose format names none
(.npy) gives None. The rules (resolve_axes):
- the scene's volume.axes, where given, must have one letter per array axis and agree with every
  axis the file names; it names the file's unnamed ones; a count after letters splits the file's
  one unnamed axis into several (split_pages: "c3zyx" reads a plain TIFF's 96 pages as 3 channels
  of 32 slices);
- without it, one unnamed axis is z where the file names no z (a plain TIFF stack's pages), a
  3D array without names is [z, y, x] (SPEC.md), and anything else is refused: reading a
  [c, z, y, x] array as 96 z-slices, as this code once did, draws a flat box a third as wide.
"""
from __future__ import annotations

import re

import numpy as np

from radiance_probes.scene.flags import with_flag
from radiance_probes.scene.types import VolumeError

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


def axis_counts(scene_axes: str) -> tuple[str, dict[str, int]]:
    """volume.axes as its letters and the counts some carry ("c3zyx": "czyx", {"c": 3})."""
    letters, counts = "", {}
    for letter, count in re.findall(r"([a-z?])([0-9]*)", scene_axes):
        letters += letter
        if count:
            counts[letter] = int(count)
    return letters, counts


def split_pages(data: np.ndarray, found: str | None, scene_axes: str | None, where: str
                ) -> tuple[np.ndarray, str | None, str | None]:
    """A file whose one unnamed axis ("?", a plain TIFF's pages) holds several axes one after
    another (tifffile writes a [c, z, y, x] array without metadata as c * z pages): the scene's
    volume.axes names more axes than the array has, and counts them ("c3zyx": 3 channels of
    pages / 3 slices; one of the split axes may go uncounted, it takes the rest). The pages are
    split in their order (the last named varying fastest). Returns the array, the file's axes and
    the scene's letters (counts dropped); an array to leave as it is passes through."""
    if scene_axes is None:
        return data, found, None
    letters, counts = axis_counts(scene_axes)
    extra = len(letters) - data.ndim
    if extra <= 0:
        if counts:
            raise VolumeError(f"{where}: {with_flag('volume.axes')} {scene_axes!r} counts "
                              f"{', '.join(counts)}, but the array's {data.ndim} axes (shape "
                              f"{list(data.shape)}) have nothing to split: counts split a TIFF's "
                              "unnamed page axis")
        return data, found, letters
    if found is None or found.count("?") != 1:
        return data, found, letters     # resolve_axes names the mismatch
    i = found.index("?")
    group = letters[i:i + extra + 1]
    outside = sorted(set(counts) - set(group))
    if outside:
        raise VolumeError(f"{where}: {with_flag('volume.axes')} {scene_axes!r} counts "
                          f"{outside[0]}, which is not among the axes the pages split into "
                          f"({', '.join(group)})")
    pages = data.shape[i]
    uncounted = [a for a in group if a not in counts]
    known = int(np.prod([counts[a] for a in group if a in counts]))
    if len(uncounted) > 1 or pages % known or (not uncounted and known != pages):
        raise VolumeError(f"{where}: {with_flag('volume.axes')} {scene_axes!r} splits the "
                          f"{pages} pages into {', '.join(group)}: count all of them but one, "
                          f"the counts dividing {pages} (e.g. "
                          f"{letters.replace(group[0], group[0] + str(_divisor(pages)), 1)})")
    sizes = [counts.get(a, pages // known) for a in group]
    shape = data.shape[:i] + tuple(sizes) + data.shape[i + 1:]
    return data.reshape(shape), found[:i] + "?" * len(group) + found[i + 1:], letters


def _divisor(n: int) -> int:
    """A small count that divides n (a plausible channel count first), for an example."""
    return next((d for d in (3, 4, 2) if n % d == 0), n)


def _describe(axes: str, shape: tuple[int, ...]) -> str:
    return "[" + ", ".join(f"{a} {n}" for a, n in zip(axes, shape)) + "]"


def resolve_axes(found: str | None, shape: tuple[int, ...], scene_axes: str | None,
                 where: str) -> str:
    """The array's axes as letters of "tczyx" (see the module's rules); raises VolumeError
    naming the axis problem."""
    ndim = len(shape)
    if scene_axes is not None:
        if any(ch.isdigit() for ch in scene_axes):
            raise VolumeError(f"{where}: {with_flag('volume.axes')} {scene_axes!r} counts axes, "
                              "which only split a multi-page TIFF's unnamed page axis")
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
