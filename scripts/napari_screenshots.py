"""The screenshots of docs/napari.md: napari's window with the plugin's widget, on the CT-like
head (its clinical preset) and on the two-channel cells, each rendered once and saved to
screenshots/. Runs napari on a private Xvfb where there is no display.

    .venv/bin/python scripts/napari_screenshots.py [--out screenshots] [--samples 16]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path


def wait_done(app, widget, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        app.processEvents()
        f = widget.last_frame
        if widget.problem or (f is not None and f.stage == "done"
                              and f.serial == widget._engine.latest):
            return
        time.sleep(0.02)
    raise SystemExit(f"no image within {timeout:.0f} s: {widget.message}")


def shoot(sample: str, out: Path, samples: int, preset: str | None, angles, method: str,
          exposure: float = 1.0) -> None:
    import napari
    from qtpy.QtWidgets import QApplication
    viewer = napari.Viewer(show=True)
    viewer.window._qt_window.resize(1200, 760)
    viewer.open_sample("radiance-probes", sample)
    viewer.dims.ndisplay = 3
    viewer.camera.angles = angles
    viewer.camera.zoom = viewer.camera.zoom * 1.25
    _, widget = viewer.window.add_plugin_dock_widget("radiance-probes", "Global illumination")
    widget.method.setCurrentText(method)
    widget.samples.setValue(samples)
    widget.render_scale.setValue(0.5)
    widget.denoise.setChecked(True)
    widget.exposure.setValue(exposure)
    if preset:
        widget.preset.setCurrentText(preset)
    app = QApplication.instance()
    for _ in range(10):
        app.processEvents()
    widget.start()
    wait_done(app, widget, 600)
    for _ in range(10):
        app.processEvents()
        time.sleep(0.05)
    viewer.screenshot(str(out), canvas_only=False)
    print(f"{out}: {widget.message}")
    widget.close_engine()
    viewer.close()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="screenshots")
    p.add_argument("--samples", type=int, default=16)
    p.add_argument("--cells-only", action="store_true", help="only the cells screenshot")
    args = p.parse_args()
    if not os.environ.get("DISPLAY"):
        from radiance_probes.viewer.xvfb import Xvfb
        xvfb = Xvfb(1280, 800)
        os.environ["DISPLAY"] = xvfb.start()
        print(f"napari on a private Xvfb {os.environ['DISPLAY']}", file=sys.stderr)
    os.environ.setdefault("QT_QPA_PLATFORM", "xcb")
    out = Path(args.out)
    out.mkdir(exist_ok=True)
    if not args.cells_only:
        shoot("ct_head", out / "napari-ct.png", args.samples, "ct_bone", (10, -35, 80), "pt",
              exposure=1.5)
    shoot("cells", out / "napari-cells.png", args.samples, None, (5, 30, 60), "pt", exposure=2.5)


if __name__ == "__main__":
    main()
