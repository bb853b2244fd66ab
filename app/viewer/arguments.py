"""The ``view`` subcommand's options (imports neither glfw nor imgui)."""
from __future__ import annotations

import argparse

from radiance_probes.frontend.scene_options import add_scene_edit_options, add_volume_options
from radiance_probes.frontend.option_types import (grid_arg, memory_size, positive_float,
                                                   positive_int, render_scale, window_size)
from radiance_probes.methods import VIEWER_METHODS as METHODS
from radiance_probes.io.scene_file import PROBE_PRECISIONS


def add_view_parser(sub, func) -> argparse.ArgumentParser:
    v = sub.add_parser("view", help="the interactive viewer: a window with panels over the same "
                                    "renderers; with --screenshot/--frames/--script it runs unattended")
    v.add_argument("scene", nargs="?", help="scene JSON or a volume file (default: built-in scene)")
    v.add_argument("--method", choices=METHODS,
                   help="render method (default: the one the scene was saved with, else pt)")
    v.add_argument("--split", choices=METHODS, metavar="METHOD",
                   help="split view: --method on the left, this method on the right")
    v.add_argument("--error-view", action="store_true",
                   help="heat map of the per-pixel difference to the path tracer")
    v.add_argument("--probe-view", nargs="?", const="over", choices=("over", "alone"),
                   help="draw the probes as spheres, over the volume (default) or alone")
    v.add_argument("--box", action="store_true", help="draw the volume's box")
    v.add_argument("--slices", nargs="?", const="three", choices=("three", "x", "y", "z"),
                   help="the slice view beside the 3D view: three orthogonal slices (default) or "
                        "the one across x, y or z")
    v.add_argument("--slice-colours", choices=("window", "tf"),
                   help="the slices in grey through the window (default) or in the transfer "
                        "function's colours")
    v.add_argument("--screenshot", metavar="PNG", help="save the window's image (panels included) "
                                                       "after the frames or the script, then exit")
    v.add_argument("--frames", type=positive_int, help="render this many frames, then exit")
    v.add_argument("--script", metavar="JSON", help="drive the viewer with a script of input "
                                                    "events (app/viewer/script.py), then exit")
    v.add_argument("--spp", type=positive_int, help="samples per pixel to stop at (default 1024)")
    v.add_argument("--window", default="1280x800", type=window_size,
                   help="window size WxH (default 1280x800)")
    v.add_argument("--render-scale", type=render_scale,
                   help="render pixels per window pixel (default 1; 0.5 on a software renderer)")
    v.add_argument("--exposure", type=positive_float,
                   help="display exposure (default: the scene's saved one, else 1)")
    v.add_argument("--probe-grid", type=grid_arg, help="probes per axis: N or NX,NY,NZ (1..256)")
    v.add_argument("--probe-samples", type=positive_int, help="walks per probe")
    v.add_argument("--sh-window", choices=("none", "hann", "lanczos"),
                   help="window on the probes' spherical harmonics against ringing near sharp "
                        "light (probes.sh_window; default none)")
    v.add_argument("--probe-precision", choices=PROBE_PRECISIONS,
                   help="the probe textures' format; rgba16f takes half the memory "
                        "(probes.precision; default auto: rgba16f with surfaces, else rgba32f)")
    v.add_argument("--seed", type=int, default=0,
                   help="random seed of the samples (default 0): the same seed, the same image")
    v.add_argument("--volume-memory", type=memory_size, metavar="BYTES",
                   help="the volume's GPU memory at most (e.g. 4G, 512M): where one 3D texture "
                        "exceeds it, the finest level whose bricks fit is shown, with a note")
    v.add_argument("--file-dialog", choices=("auto", "builtin"), default="auto",
                   help="auto: the system's file dialog where one is installed (zenity, kdialog), "
                        "else the viewer's own; builtin: always the viewer's own")
    add_volume_options(v)
    add_scene_edit_options(v)
    v.set_defaults(func=func)
    return v

