"""The command line's option types, each checking its value and refusing it in one line that names
the option: counts, fractions, sizes, grids, windows, spacing, ranges, channels, opacity points,
`--set KEY=VALUE`, surfaces, memory sizes; and the parser that prints those refusals."""
from __future__ import annotations

import argparse
import json
import math
import re


MAX_SPP = (1 << 31) - 1        # samples per pixel reach the shaders as a 32-bit uniform


MAX_WINDOW_SIDE = 16384


MAX_RENDER_SCALE = 4.0


DEFAULT_RAYMARCH_STEP = 0.5    # voxels; --raymarch-step's default (None: not given)


class OptionError(ValueError):
    """A command-line option that cannot work (a path that cannot be written, a bad combination);
    the message names the option."""


def positive_int(text: str, limit: int = MAX_SPP) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if not 1 <= v <= limit:
        raise argparse.ArgumentTypeError(f"expected an integer from 1 to {limit}, got {text!r}")
    return v


def positive_float(text: str) -> float:
    """A finite number > 0 (exposures, steps, scales): nan, inf, 0 and negatives are refused."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0.0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return v


def fraction(text: str) -> float:
    """A finite number in (0, 1] (a relative error target)."""
    v = positive_float(text)
    if v > 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in (0, 1], got {text!r}")
    return v


def render_scale(text: str) -> float:
    """Render pixels per window pixel: finite, in (0, MAX_RENDER_SCALE]."""
    v = positive_float(text)
    if v > MAX_RENDER_SCALE:
        raise argparse.ArgumentTypeError(f"expected a number in (0, {MAX_RENDER_SCALE}], got {text!r}")
    return v


def grid_arg(text: str) -> list[int]:
    parts = text.split(",")
    if len(parts) not in (1, 3):
        raise argparse.ArgumentTypeError(f"expected N or NX,NY,NZ, got {text!r}")
    values = [positive_int(p) for p in parts]
    return values * 3 if len(values) == 1 else values


def window_size(text: str) -> tuple[int, int]:
    w, sep, h = text.lower().partition("x")
    try:
        size = (int(w), int(h))
    except ValueError:
        size = (0, 0)
    if not sep or min(size) < 64 or max(size) > MAX_WINDOW_SIDE:
        raise argparse.ArgumentTypeError(f"expected WxH from 64x64 to {MAX_WINDOW_SIDE}x"
                                         f"{MAX_WINDOW_SIDE}, got {text!r}")
    return size


class ArgumentParser(argparse.ArgumentParser):
    """argparse with its errors as one line (``radiance-probes render: error: ...``), exit 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def series_arg(text: str) -> int | str:
    """--series: a number in the folder's listing (from 1) or a SeriesInstanceUID."""
    text = text.strip()
    if text.isdigit():
        if int(text) < 1:
            raise argparse.ArgumentTypeError(f"expected a series number from 1 or a "
                                             f"SeriesInstanceUID, got {text!r}")
        return int(text)
    if not text:
        raise argparse.ArgumentTypeError("expected a series number or a SeriesInstanceUID")
    return text


def window_arg(text: str) -> str | dict:
    """--window: a preset name (soft_tissue, bone, lung, air) or LEVEL,WIDTH in data units."""
    from radiance_probes.scene.types import WINDOW_PRESETS
    if text.strip().lower() in WINDOW_PRESETS:
        return text.strip().lower()
    parts = text.split(",")
    try:
        level, width = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a preset ({', '.join(WINDOW_PRESETS)}) or "
                                         f"LEVEL,WIDTH, got {text!r}") from None
    return {"level": level, "width": width}


def _numbers(text: str, n: int | None, what: str) -> list[float]:
    """`n` finite numbers separated by commas (any count where n is None)."""
    try:
        values = [float(t) for t in text.replace(" ", "").split(",")]
    except ValueError:
        values = []
    if not values or (n is not None and len(values) != n) or not all(map(math.isfinite, values)):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    return values


def spacing_arg(text: str) -> list[float]:
    """--spacing: X,Y,Z voxel sizes > 0 (or one size for all three)."""
    values = _numbers(text, None, "X,Y,Z: three voxel sizes > 0 (or one for all three)")
    if len(values) == 1:
        values *= 3
    if len(values) != 3 or min(values) <= 0:
        raise argparse.ArgumentTypeError(f"expected X,Y,Z: three voxel sizes > 0 (or one for all "
                                         f"three), got {text!r}")
    return values


def value_range_arg(text: str) -> list[float]:
    """--value-range: LO,HI data values, LO < HI."""
    lo, hi = _numbers(text, 2, "LO,HI: the data values shown as density 0 and 1")
    if not hi > lo:
        raise argparse.ArgumentTypeError(f"expected LO,HI with LO < HI, got {text!r}")
    return [lo, hi]


def dims_arg(text: str) -> list[int]:
    """--dims: X,Y,Z voxel counts of a .raw file."""
    values = _numbers(text, 3, "X,Y,Z: three voxel counts")
    if not all(v.is_integer() and v >= 1 for v in values):
        raise argparse.ArgumentTypeError(f"expected X,Y,Z: three whole voxel counts >= 1, got "
                                         f"{text!r}")
    return [int(v) for v in values]


def finite_float(text: str) -> float:
    return _numbers(text, 1, "a finite number")[0]


def time_arg(text: str) -> int:
    """--time: a time step from 0."""
    try:
        v = int(text)
    except ValueError:
        v = -1
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected a time step 0, 1, 2, ..., got {text!r}")
    return v


def channel_arg(text: str) -> list[int]:
    """--channel: the file's channels to show, I or I,J,... from 0."""
    try:
        values = [int(t) for t in text.replace(" ", "").split(",")]
    except ValueError:
        values = []
    if not values or min(values) < 0 or len(set(values)) != len(values):
        raise argparse.ArgumentTypeError(f"expected the file's channels to show, I or I,J,... "
                                         f"(from 0, each once), got {text!r}")
    return values


def opacity_arg(text: str) -> list[list[float]]:
    """--opacity: [density, opacity] points as D,A,D,A,... (or their JSON list), each in [0, 1],
    densities not decreasing."""
    expected = ("D,A,D,A,...: [density, opacity] points, each in [0, 1], densities not "
                "decreasing (e.g. 0,0,0.3,0,1,1)")
    try:
        data = json.loads(text)
        flat = [float(v) for point in data for v in point] if isinstance(data, list) else []
    except (ValueError, TypeError):
        flat = _numbers(text, None, expected)
    if not flat or len(flat) % 2 or not all(math.isfinite(v) and 0 <= v <= 1 for v in flat):
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
    points = [flat[i:i + 2] for i in range(0, len(flat), 2)]
    if any(b[0] < a[0] for a, b in zip(points, points[1:])):
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
    return points


_SET_KEY = re.compile(r"[a-z_]+(\[\d+\])?(\.[a-z_]+(\[\d+\])?)*")


def set_value(text: str):
    """A --set value: JSON where it parses (1.5, [1, 1, 2], true, "text", {...}), else a comma
    list of numbers (1,1,2), else the text itself (czyx, grey)."""
    try:
        return json.loads(text)
    except ValueError:
        pass
    if "," in text:
        try:
            return [float(t) if not t.strip().lstrip("+-").isdigit() else int(t)
                    for t in text.split(",")]
        except ValueError:
            pass
    return text


def set_arg(text: str) -> tuple[str, object, str]:
    """--set KEY=VALUE: (the scene key, its value, the text given)."""
    key, sep, value = text.partition("=")
    key = key.strip()
    if not sep or not _SET_KEY.fullmatch(key):
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE with a scene key of "
                                         f"docs/scene-format.md (e.g. --set volume.spacing=1,1,2), got "
                                         f"{text!r}")
    return key, set_value(value.strip()), text


def surface_arg(text: str) -> dict:
    """--surface K[,ROUGHNESS[,SPECULAR]]: the scene's surface key (checked as the scene's is)."""
    parts = [p.strip() for p in text.split(",")]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if not 1 <= len(values) <= 3 or len(values) != len(parts):
        raise argparse.ArgumentTypeError(f"expected K, K,ROUGHNESS or K,ROUGHNESS,SPECULAR (numbers), "
                                         f"got {text!r}")
    out: dict = {"gradient_factor": values[0]}
    if len(values) > 1:
        out["roughness"] = values[1]
    if len(values) > 2:
        out["specular"] = [values[2]] * 3
    return out


def memory_size(text: str) -> int:
    """Bytes from "4G", "512M", "65536" (K, M, G, T: powers of 1024)."""
    units = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
    t = text.strip().upper().removesuffix("B").removesuffix("I")
    scale = units.get(t[-1:], 1)
    number = t[:-1] if t[-1:] in units else t
    try:
        value = int(float(number) * scale)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a size in bytes such as 4G or 512M, got "
                                         f"{text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a size > 0, got {text!r}")
    return value
