"""The dock widget "Global illumination": napari's visible image layers and camera rendered with
this project's renderers (layers.py, camera_map.py), in a worker process (engine.py), shown over
napari's canvas (overlay.py). The raymarcher draws while the camera moves (at most one request
per THROTTLE_MS, each superseding the last); once it is still, the chosen method refines with
progress and the estimated error; Denoise filters the last image. The controls carry the viewer's
names and ranges (app/frontend/controls.py). A layer that cannot be rendered gets a message here, never a
traceback."""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from qtpy.QtCore import QObject, QTimer, Signal
from qtpy.QtWidgets import (QCheckBox, QComboBox, QDoubleSpinBox, QFileDialog, QFormLayout,
                            QHBoxLayout, QLabel, QProgressBar, QPushButton, QSpinBox,
                            QVBoxLayout, QWidget)

from radiance_probes.frontend import controls as C
from radiance_probes.scene.clinical_presets import CLINICAL_PRESETS
from radiance_probes.methods import VIEWER_METHODS
from radiance_probes.scene.types import LightSpec, Scene
from radiance_probes.napari_plugin.camera_map import camera_from_viewer, napari_camera
from radiance_probes.napari_plugin.engine import Frame, RenderEngine, Request
from radiance_probes.napari_plugin.layers import LayerProblem, layer_scene
from radiance_probes.napari_plugin.overlay import CanvasOverlay, OverlayError, canvas_size

THROTTLE_MS = 40          # a camera move waits this long for the next before it is sent
REDRAW_MS = 250           # refinement rounds redraw napari's canvas at most this often (each
#                           redraw draws napari's own layers too: slow on llvmpipe)
DEFAULT_SAMPLES = 16      # the still image's samples (Max samples)
NO_PRESET = "(none)"
LAYER_EVENTS = ("contrast_limits", "colormap", "gamma", "opacity", "visible", "data", "scale",
                "translate", "rendering")


class _Bridge(QObject):
    """Carries the engine's frames and errors from its reader thread onto Qt's."""
    frame = Signal(object)
    error = Signal(str)


def _direction(azimuth_deg: float, elevation_deg: float) -> list[float]:
    from radiance_probes.viewer.state import direction_from_angles
    return [float(c) for c in direction_from_angles(azimuth_deg, elevation_deg)]


def _spin(control: C.Control, value: float):
    box = QSpinBox() if control.integer else QDoubleSpinBox()
    if not control.integer:
        box.setDecimals(3 if control.hi <= 1.0 else 2)
        box.setSingleStep((control.hi - control.lo) / 100.0)
    box.setRange(control.lo, control.hi)
    box.setValue(int(value) if control.integer else float(value))
    if control.unit:
        box.setSuffix(f" {control.unit}")
    return box


class GlobalIlluminationWidget(QWidget):
    """napari's dock widget; `viewer` is napari's Viewer (npe2 passes it)."""

    def __init__(self, napari_viewer, gl_backend: str | None = None):
        super().__init__()
        self.viewer = napari_viewer
        self._bridge = _Bridge()
        self._bridge.frame.connect(self._on_frame)
        self._bridge.error.connect(self._on_error)
        self._engine: RenderEngine | None = None
        self._gl_backend = gl_backend
        self._scene = None                # layers.LayerScene, until a layer changes
        self._request: Request | None = None
        self._shown_serial = 0
        self._shown_at = 0.0              # when the overlay was last redrawn (monotonic s)
        self.last_frame: Frame | None = None
        self.message = ""
        self.problem = False              # the status line names a problem
        self.live = False
        self._overlay: CanvasOverlay | None = None
        self._movie: subprocess.Popen | None = None
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(THROTTLE_MS)
        self._timer.timeout.connect(self._send)
        self._build()
        self._connect_viewer()

    # ---- the panel ---------------------------------------------------------------------------
    def _build(self) -> None:
        light = LightSpec()
        from radiance_probes.viewer.state import angles_from_direction
        az, el = angles_from_direction(light.direction)
        form = QFormLayout()
        self.method = QComboBox()
        self.method.addItems(list(VIEWER_METHODS))
        self.method.setCurrentText("raymarch")
        self.denoise = QCheckBox()
        self.samples = _spin(C.MAX_SAMPLES, DEFAULT_SAMPLES)
        self.render_scale = _spin(C.RENDER_SCALE, 1.0)
        self.exposure = _spin(C.EXPOSURE, 1.0)
        self.probes_per_axis = _spin(C.PROBES_PER_AXIS, 16)
        self.walks = _spin(C.WALKS_PER_PROBE, 256)
        self.sun_azimuth = _spin(C.SUN_AZIMUTH, az)
        self.sun_elevation = _spin(C.SUN_ELEVATION, el)
        self.sun_strength = _spin(C.SUN_STRENGTH, max(light.irradiance))
        self.environment = _spin(C.ENVIRONMENT_STRENGTH, max(Scene().environment))
        self.preset = QComboBox()
        self.preset.addItems([NO_PRESET, *CLINICAL_PRESETS])
        self.surface_k = _spin(C.SURFACE_K, 0.0)
        self.roughness = _spin(C.ROUGHNESS, 0.3)
        rows = [(C.METHOD, self.method), (C.DENOISE, self.denoise),
                (C.MAX_SAMPLES.label, self.samples), (C.RENDER_SCALE.label, self.render_scale),
                (C.EXPOSURE.label, self.exposure), (C.PROBES_PER_AXIS.label, self.probes_per_axis),
                (C.WALKS_PER_PROBE.label, self.walks), (C.SUN_AZIMUTH.label, self.sun_azimuth),
                (C.SUN_ELEVATION.label, self.sun_elevation),
                (C.SUN_STRENGTH.label, self.sun_strength),
                (C.ENVIRONMENT_STRENGTH.label, self.environment), (C.CT_PRESET, self.preset),
                (C.SURFACE_K.label, self.surface_k), (C.ROUGHNESS.label, self.roughness)]
        for label, field in rows:
            form.addRow(label, field)
            signal = getattr(field, "valueChanged", None) or getattr(field, "currentTextChanged",
                                                                     None)
            if isinstance(field, QCheckBox):
                signal = field.toggled
            if field is self.exposure:
                signal.connect(self._retone)
            else:
                signal.connect(self._controls_changed)
        self.render_button = QPushButton("Render")
        self.render_button.setToolTip("Render the visible image layers lit, and follow the camera")
        self.render_button.clicked.connect(self.start)
        self.stop_button = QPushButton("Stop")
        self.stop_button.clicked.connect(self.stop)
        buttons = QHBoxLayout()
        buttons.addWidget(self.render_button)
        buttons.addWidget(self.stop_button)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        self.status = QLabel("Press Render: the visible image layers, lit, over napari's view.")
        self.status.setWordWrap(True)
        self.save_image_button = QPushButton("Save image...")
        self.save_image_button.clicked.connect(lambda: self._ask_path(
            "Save image", "PNG (*.png);;OpenEXR (*.exr)", self.save_image))
        self.save_scene_button = QPushButton("Save scene...")
        self.save_scene_button.clicked.connect(lambda: self._ask_path(
            "Save scene", "Scene (*.json)", self.save_scene))
        self.turntable_button = QPushButton("Turntable...")
        self.turntable_button.clicked.connect(lambda: self._ask_path(
            "Turntable movie", "MP4 (*.mp4);;GIF (*.gif)", self.record_turntable))
        outputs = QHBoxLayout()
        for b in (self.save_image_button, self.save_scene_button, self.turntable_button):
            outputs.addWidget(b)
        layout = QVBoxLayout(self)
        layout.addLayout(buttons)
        layout.addWidget(self.progress)
        layout.addWidget(self.status)
        layout.addLayout(form)
        layout.addLayout(outputs)
        layout.addStretch(1)

    def _ask_path(self, title: str, filters: str, action) -> None:
        path, _ = QFileDialog.getSaveFileName(self, title, "", filters)
        if path:
            action(path)

    # ---- napari's events -----------------------------------------------------------------------
    def _connect_viewer(self) -> None:
        cam = napari_camera(self.viewer).events
        for name in ("center", "zoom", "angles", "perspective"):
            getattr(cam, name).connect(self._camera_moved)
        self.viewer.dims.events.ndisplay.connect(self._layers_changed)
        self.viewer.dims.events.current_step.connect(self._layers_changed)
        self.viewer.dims.events.order.connect(self._layers_changed)
        self.viewer.layers.events.inserted.connect(self._layer_added)
        self.viewer.layers.events.removed.connect(self._layers_changed)
        self.viewer.layers.events.moved.connect(self._layers_changed)
        for layer in self.viewer.layers:
            self._watch(layer)

    def _watch(self, layer) -> None:
        for name in LAYER_EVENTS:
            event = getattr(layer.events, name, None)
            if event is not None:
                event.connect(self._layers_changed)

    def _layer_added(self, event) -> None:
        self._watch(event.value)
        self._layers_changed()

    def _layers_changed(self, event=None) -> None:
        self._scene = None
        if self.live:
            self._timer.start()

    def _camera_moved(self, event=None) -> None:
        if self.live and not self._timer.isActive():
            self._timer.start()

    def _controls_changed(self, *args) -> None:
        if self.live:
            self._timer.start()

    # ---- rendering -----------------------------------------------------------------------------
    def start(self) -> None:
        """The Render button: render now, and again whenever the camera or a layer changes."""
        self.live = True
        self._send()

    def stop(self) -> None:
        self.live = False
        self._timer.stop()
        if self._overlay is not None:
            self._overlay.hide()
        self._say("Stopped: napari's own rendering is shown.")

    def scene_options(self) -> dict:
        """The render()/Renderer keyword options of the layers and the controls (no camera)."""
        scene = self._layer_scene()
        options = json.loads(json.dumps(scene.options))
        n = int(self.probes_per_axis.value())
        options["probes"] = {"grid": [n, n, n], "samples": int(self.walks.value())}
        s = float(self.sun_strength.value())
        options["light"] = {"direction": _direction(self.sun_azimuth.value(),
                                                    self.sun_elevation.value()),
                            "irradiance": [s, s, s]}
        e = float(self.environment.value())
        options["environment"] = [e, e, e]
        preset = self.preset.currentText()
        if preset != NO_PRESET:
            if "channels" in options:
                raise LayerProblem("clinical presets are for one CT layer: hide the other "
                                   "layers or choose CT preset (none)")
            options["transfer_function"] = {"preset": preset}
        k = float(self.surface_k.value())
        if k > 0 or preset == NO_PRESET:
            options["surface"] = {"gradient_factor": k, "roughness": float(self.roughness.value())}
        return options

    def _layer_scene(self):
        if self._scene is None:
            self._scene = layer_scene(self.viewer)
        return self._scene

    def camera(self) -> dict:
        """Our camera for napari's, at the view box's size times Render scale."""
        w, h = canvas_size(self.viewer)
        scale = float(self.render_scale.value())
        return camera_from_viewer(self.viewer, w, h, self._layer_scene().placement, scale)

    def request(self) -> Request:
        """What the next render is (raises LayerProblem or ValueError with the reason)."""
        options = self.scene_options()
        return Request(self._layer_scene().data, options, self.camera(),
                       method=self.method.currentText(), max_samples=int(self.samples.value()),
                       denoise=self.denoise.isChecked(), preview_scale=0.5)

    def _send(self) -> None:
        try:
            request = self.request()
            self._check_options(request)
        except (LayerProblem, ValueError) as exc:
            self._say(str(exc), problem=True)
            if self._overlay is not None:
                self._overlay.hide()
            return
        if self._engine is None:
            self._engine = RenderEngine(self._bridge.frame.emit, self._bridge.error.emit,
                                        self._gl_backend)
            self._say("Starting the renderer (a GL context, the shaders and the probes)...")
        self._request = request
        self._engine.submit(request)
        if self.problem:   # the problem is gone: say what happens instead
            self._say(f"Rendering {', '.join(self._layer_scene().names)}...")

    @staticmethod
    def _check_options(request: Request) -> None:
        """The scene the request makes, checked here (a message now, not the worker's later)."""
        from radiance_probes.api.render import _merge
        from radiance_probes.io.scene_file import SceneError, parse_scene
        merged = _merge({}, {k: v for k, v in request.options.items()
                             if k not in ("spacing", "value_range", "axes", "channels")})
        try:
            parse_scene(merged)
        except SceneError as exc:
            raise ValueError(str(exc)) from None

    def _on_frame(self, frame: Frame) -> None:
        if frame.serial < self._shown_serial or not self.live:
            return
        self._shown_serial = frame.serial
        self.last_frame = frame
        now = time.monotonic()
        if frame.stage != "refining" or now - self._shown_at >= REDRAW_MS / 1e3:
            self._show(frame)
            self._shown_at = now
        self.progress.setValue(int(round(1000 * frame.progress)) if frame.stage != "preview"
                               else 0)
        if frame.stage == "preview":
            text = f"raymarch preview ({frame.ms:.0f} ms); refining with {frame.method}..."
        else:
            err = (f", estimated error {100 * frame.error:.1f}% rRMSE" if frame.error is not None
                   else "" if not _estimated(frame.method) else ", error: after 2 rounds")
            text = (f"{frame.method}: {frame.samples} / {frame.max_samples} samples{err}"
                    + (", denoised" if frame.denoised else "") + f" ({frame.ms:.0f} ms)")
            notes = [n for n in frame.notes if "denois" in n.lower()]
            if notes:
                text += f". {notes[-1]}"
        self._say(text)

    def _on_error(self, text: str) -> None:
        self._say(f"Could not render: {text}", problem=True)

    def _show(self, frame: Frame) -> None:
        from radiance_probes.rendering.tonemap import to_uint8
        srgb = to_uint8(frame.image, float(self.exposure.value()))
        if self._overlay is None:
            try:
                self._overlay = CanvasOverlay(self.viewer)
            except OverlayError as exc:
                self._say(str(exc), problem=True)
                return
        self._overlay.show(srgb)

    def _retone(self, *args) -> None:
        if self.last_frame is not None and self.live:
            self._show(self.last_frame)

    def _say(self, text: str, problem: bool = False) -> None:
        self.message = text
        self.problem = problem
        self.status.setText(text)
        self.status.setStyleSheet("color: #ff8c69;" if problem else "")

    # ---- output ---------------------------------------------------------------------------------
    def save_image(self, path: str) -> Path | None:
        """The last image as PNG (tone-mapped at Exposure) or EXR (linear)."""
        from radiance_probes.frontend.imageio import save_exr, save_png
        if self.last_frame is None:
            self._say("Nothing rendered yet: press Render first.", problem=True)
            return None
        p = Path(path)
        if p.suffix.lower() == ".exr":
            out = save_exr(p, self.last_frame.image)
        elif p.suffix.lower() == ".png":
            out = save_png(p, self.last_frame.image, float(self.exposure.value()))
        else:
            self._say(f"{p.name}: give a .png or .exr file name", problem=True)
            return None
        self._say(f"Saved {out}")
        return out

    def scene_dict(self, volume_file: str) -> dict:
        """The scene file's contents: the layers' array saved as `volume_file` (.npy, the slices
        as the renderer holds them), the controls and the camera."""
        from radiance_probes.api.render import _merge
        options = self.scene_options()
        volume = {"path": volume_file, "spacing": options.pop("spacing")}
        if "value_range" in options:
            volume["value_range"] = options.pop("value_range")
        if "axes" in options:
            volume["axes"] = options.pop("axes")
        scene = _merge({}, options)
        scene["volume"] = volume
        scene["camera"] = self.camera()
        return scene

    def save_scene(self, path: str) -> Path | None:
        """A scene file (and its volume beside it, NAME.npy) that `radiance-probes render` draws
        as the plugin does: `render SCENE --method M --spp N` gives the same image."""
        p = Path(path)
        if p.suffix.lower() != ".json":
            p = p.with_suffix(".json")
        try:
            volume_path = p.with_suffix(".npy")
            scene = self.scene_dict(volume_path.name)
            np.save(volume_path, self._layer_scene().data)
        except (LayerProblem, ValueError) as exc:
            self._say(str(exc), problem=True)
            return None
        p.write_text(json.dumps(scene, indent=2))
        method = self.method.currentText()
        self._say(f"Saved {p} (and {volume_path.name}); the command line renders it with: "
                  f"radiance-probes render {p.name} --method {method} --spp "
                  f"{int(self.samples.value())}")
        return p

    def record_turntable(self, path: str, frames: int = 120) -> subprocess.Popen | None:
        """A turntable movie about napari's view through `radiance-probes animate`, in a process
        of its own; the status line says when it is written."""
        folder = Path(tempfile.mkdtemp(prefix="radiance-probes-napari-"))
        scene = self.save_scene(str(folder / "scene.json"))
        if scene is None:
            return None
        method = self.method.currentText()
        from radiance_probes.methods import MOVIE_METHODS
        if method not in MOVIE_METHODS:
            method = "raymarch"
        argv = [sys.executable, "-m", "radiance_probes", "animate", str(scene), "--turntable",
                "360", "--frames", str(int(frames)), "--out", str(Path(path).resolve()),
                "--method", method]
        if Path(path).suffix.lower() == ".mp4":   # H.264 in yuv420p: even sizes, one pixel more
            cam = json.loads(scene.read_text())["camera"]
            argv += ["--width", str(cam["width"] + cam["width"] % 2),
                     "--height", str(cam["height"] + cam["height"] % 2)]
        self._movie = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                       text=True)
        self._movie_path = Path(path)
        self._movie_timer = QTimer(self)
        self._movie_timer.timeout.connect(self._check_movie)
        self._movie_timer.start(500)
        self._say(f"Recording a turntable of {frames} frames ({method}) to {path}...")
        return self._movie

    def _check_movie(self) -> None:
        if self._movie is None or self._movie.poll() is None:
            return
        self._movie_timer.stop()
        err = self._movie.stderr.read() if self._movie.stderr else ""
        if self._movie.returncode == 0:
            self._say(f"Turntable written: {self._movie_path}")
        else:
            last = err.strip().splitlines()[-1] if err.strip() else f"exit {self._movie.returncode}"
            self._say(f"The turntable failed: {last}", problem=True)
        self._movie = None

    # ---- closing --------------------------------------------------------------------------------
    def close_engine(self) -> None:
        if self._engine is not None:
            self._engine.close()
            self._engine = None

    def closeEvent(self, event) -> None:
        self.close_engine()
        super().closeEvent(event)

    def deleteLater(self) -> None:
        self.close_engine()
        super().deleteLater()


def _estimated(method: str) -> bool:
    """The method's still image is refined in rounds with an error estimate."""
    from radiance_probes.methods import METHODS
    return METHODS[method].noisy and not METHODS[method].composite
