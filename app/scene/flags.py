"""Which command-line flag sets each scene key, so that a message naming a key can name the flag
too ("give volume.spacing (--spacing X,Y,Z)"): a key with a flag of its own names it, any other
key `--set KEY=VALUE` (which sets every key). Imports nothing of the package, so that the loaders
can use it."""
from __future__ import annotations

import re

# scene key -> (its flag, the flag's value as the help shows it)
FLAGS: dict[str, tuple[str, str]] = {
    "volume.spacing": ("--spacing", "X,Y,Z"),
    "volume.value_range": ("--value-range", "LO,HI"),
    "volume.window": ("--data-window", "PRESET|LEVEL,WIDTH"),
    "volume.dims": ("--dims", "X,Y,Z"),
    "volume.dtype": ("--dtype", "TYPE"),
    "volume.axes": ("--axes", "LETTERS"),
    "volume.replace_nonfinite": ("--replace-nonfinite", "VALUE"),
    "volume.series": ("--series", "N|UID"),
    "volume.orientation": ("--orientation", "data|patient"),
    "transfer_function.colormap": ("--colormap", "NAME"),
    "transfer_function.opacity": ("--opacity", "D,A,D,A,..."),
    "time": ("--time", "STEP"),
    "channels": ("--channel", "I[,J,...]"),
    "channels[].index": ("--channel", "I[,J,...]"),
    "camera.width": ("--width", "PIXELS"),
    "camera.height": ("--height", "PIXELS"),
    "probes.grid": ("--probe-grid", "N|NX,NY,NZ"),
    "probes.samples": ("--probe-samples", "N"),
    "probes.sh_window": ("--sh-window", "none|hann|lanczos"),
    "probes.precision": ("--probe-precision", "auto|rgba32f|rgba16f"),
    "probes.layout": ("--probe-layout", "uniform|adaptive"),
    "probes.adaptive_strength": ("--adaptive-strength", "S"),
    "probes.adaptive_indicator": ("--adaptive-indicator", "extinction|sun"),
    "probes.interpolation": ("--probe-interpolation", "trilinear|visibility"),
    "crop": ("--crop", "X0 Y0 Z0 X1 Y1 Z1"),
    "clip_plane": ("--clip-plane", "NX NY NZ D"),
}

# A transfer function's colours come from one of these: setting one drops the others the scene
# had (a colormap given after colour points, rgba rows after a colormap).
COLOUR_SOURCES = {"colormap": ("colors", "rgba"), "colors": ("colormap", "rgba"),
                  "rgba": ("colormap", "colors", "opacity"), "opacity": ("rgba",)}
# Keys that exclude each other in one object: setting one drops the other.
EXCLUDES = {"volume": {"window": ("value_range",), "value_range": ("window",),
                       "path": ("builtin", "size"), "builtin": ("path",)},
            "transfer_function": COLOUR_SOURCES}

# A scene key as messages write it: dotted words, with [i], [0] or [] after a list's name.
KEY_PATTERN = re.compile(r"\b[a-z_]+(?:\[[a-z0-9]*\])?(?:\.[a-z_]+(?:\[[a-z0-9]*\])?)+")


def generic(key: str) -> str:
    """The key with its list indices as the key table writes them: channels[2].window ->
    channels[].window."""
    return re.sub(r"\[[a-z0-9]*\]", "[]", key)


def flag_for(key: str) -> str:
    """The flag that sets `key`, with its value: "--spacing X,Y,Z", else "--set KEY=VALUE"."""
    flag = FLAGS.get(generic(key))
    if flag is None:
        return f"--set {key}=VALUE"
    return f"{flag[0]} {flag[1]}"


def with_flag(key: str) -> str:
    """The key and the flag that sets it, for a message: "volume.spacing (--spacing X,Y,Z)"."""
    return f"{key} ({flag_for(key)})"
