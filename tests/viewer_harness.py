"""Helpers for tests/test_viewer.py: run the real viewer (``python -m radiance_probes view``) in a real window
on a private Xvfb, read its screenshots and state dumps.

Run as a script it is the viewer with test hooks:
  python tests/viewer_harness.py --glsl DIR -- view ARGS...   the shaders come from DIR
  python tests/viewer_harness.py --release-check -- view ARGS... after the run, every GPU object
                                    the viewer made must have been released when it closed
  --lazy-bytes N                    Zarr stores larger than N bytes are read brick by brick
  --open-delay S                    a volume opening on a thread starts S seconds late
  --load-after PATH                 a file opened in the window is read once PATH exists (a dump)
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HARNESS = Path(__file__).resolve()
RUN_TIMEOUT = 240


def view(args: list[str], cwd: Path, display: str | None, timeout: int = RUN_TIMEOUT,
         harness: list[str] | None = None, check: bool = True,
         env: dict | None = None) -> subprocess.CompletedProcess:
    """Runs ``radiance-probes view ARGS`` (through the harness when given hooks)."""
    env = {**os.environ, **(env or {})}
    env.pop("DISPLAY", None)
    env.pop("WAYLAND_DISPLAY", None)
    if display:
        env["DISPLAY"] = display
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    if harness is None:
        cmd = [sys.executable, "-m", "radiance_probes", "view", *args]
    else:
        cmd = [sys.executable, str(HARNESS), *harness, "--", "view", *args]
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    if check and proc.returncode != 0:
        raise AssertionError(f"view exited {proc.returncode}\nstdout:\n{proc.stdout}\nstderr:\n{proc.stderr}")
    return proc


def png(path: Path) -> np.ndarray:
    from PIL import Image
    return np.asarray(Image.open(path).convert("RGB")).astype(np.int16)


def dump(path: Path) -> dict:
    return json.loads(Path(path).read_text())


LABEL_BAND = 32   # rows at the top of the view where the method labels are drawn


def view_pixels(image: np.ndarray, d: dict) -> np.ndarray:
    """The picture's part of a screenshot (the sidebar and the label band cut off)."""
    x, y, w, h = d["view_rect_framebuffer"]
    height = image.shape[0]
    top = height - (y + h)
    return image[top + LABEL_BAND: top + h, x: x + w]


def srgb8(linear) -> np.ndarray:
    from radiance_probes.rendering.tonemap import to_uint8
    return to_uint8(np.asarray(linear, np.float64)).astype(np.int16)


def write_script(path: Path, steps: list[dict]) -> Path:
    path.write_text(json.dumps(steps, indent=1))
    return path


# ---- the hooks, when run as a script ------------------------------------------------------------

def _release_check(argv: list[str]) -> int:
    """Runs the viewer, remembers its GPU objects before the window closes, checks them after."""
    import moderngl

    import radiance_probes.viewer.window as window_module
    from radiance_probes.cli.main import main

    seen: list = []
    original_close = window_module.ViewerWindow.close

    def close(self) -> None:
        v = self.viewer
        s = v.session
        seen.extend(view.acc.texture for view in s.views.values() if view.acc is not None)
        if s.probe_grid is not None:
            seen.extend(s.probe_grid.textures)
        transfer = s.renderer.resources.transfer_gpu
        seen.extend([s.renderer.resources.volume_tex, transfer.texture, transfer.buffer])
        seen.extend(p.program for p in v._passes.values())
        original_close(self)

    window_module.ViewerWindow.close = close
    rc = main(argv)
    live = [o for o in seen if not isinstance(o.mglo, moderngl.InvalidObject)]
    print(f"release check: {len(seen)} GPU objects, {len(live)} still alive")
    return rc if not live else 5


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    split = sys.argv.index("--")
    hooks, view_argv = sys.argv[1:split], sys.argv[split + 1:]
    if "--glsl" in hooks:   # the one place that reads shader files (the GPU layer is given it)
        import radiance_probes.rendering.shader_files as shader_files
        shader_files.GLSL_DIR = Path(hooks[hooks.index("--glsl") + 1])
    if "--lazy-bytes" in hooks:   # Zarr stores larger than this are read brick by brick
        import radiance_probes.io.lazy_zarr
        radiance_probes.io.lazy_zarr.LAZY_BYTES = int(hooks[hooks.index("--lazy-bytes") + 1])
    if "--open-delay" in hooks:   # a volume opening on a thread starts this many seconds late
        import time as _time
        from radiance_probes.rendering.levels.progressive_open import ProgressiveOpen
        delay, work = float(hooks[hooks.index("--open-delay") + 1]), ProgressiveOpen._work
        ProgressiveOpen._work = lambda self: (_time.sleep(delay), work(self))[1]
    if "--load-after" in hooks:   # a file opened in the window is read once this file exists
        import time as _time
        from radiance_probes.viewer.opening import VolumeLoading
        gate, read = Path(hooks[hooks.index("--load-after") + 1]), VolumeLoading._work

        def gated(self):
            deadline = _time.monotonic() + 120.0
            while not gate.exists() and _time.monotonic() < deadline:
                _time.sleep(0.01)
            read(self)
        VolumeLoading._work = gated
    if "--release-check" in hooks:
        sys.exit(_release_check(view_argv))
    from radiance_probes.cli.main import main
    sys.exit(main(view_argv))
