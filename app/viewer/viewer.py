"""The viewer without its window: per frame it applies what the user changed, advances the
renderers, draws the picture (display pass, probe spheres, volume box) and builds the panels.
Errors (a scene that does not load, a shader that does not compile, a GL error) go to the error
panel; the viewer keeps running with what last worked."""
from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path

import moderngl
import numpy as np

from radiance_probes.methods import REFERENCE
from radiance_probes.twins.camera import camera_frame
from radiance_probes.gl.shaders import ShaderError
from radiance_probes.gl.timer import GpuTimer
from radiance_probes.io.scene_file import SceneError, scene_to_dict
from radiance_probes.io.environment_map import load_scene_environment
from radiance_probes.scene.channels import volume_inputs
from radiance_probes.rendering.levels.progressive_open import OPEN_WRITE_BUDGET_S, ProgressiveOpen
from radiance_probes.rendering.levels.volume_placement import device_limits
from radiance_probes.scene.clinical_presets import opening_scene
from radiance_probes.io.volume import VolumeError
from radiance_probes.io.load import reads_lazily, zarr_preview
from radiance_probes.viewer import layout, orbit, overlays
from radiance_probes.viewer.panels import sidebar as panels
from radiance_probes.viewer.display import BACKGROUND, DisplayPass, ErrorMeter
from radiance_probes.viewer.opening import VolumeLoading
from radiance_probes.viewer.files import FileDialogs, builtin_scene, datasets, scene_for_path
from radiance_probes.viewer import crop_handles
from radiance_probes.viewer.probe_view import (BoxOutline, ProbeSpheres, describe_probe,
                                               probe_centres, probe_under, slab_plane)
from radiance_probes.viewer.recorder import MovieRecorder
from radiance_probes.viewer.frame.views import FrameTimes
from radiance_probes.viewer.frame.session import RenderSession
from radiance_probes.viewer.panels.slice_panel import SliceImages, SlicePanel
from radiance_probes.viewer.state import ViewerState
from radiance_probes.scene.transfer import opacity_points
from radiance_probes.viewer.panels.tf_editor import histogram_curve
from radiance_probes.viewer.widgets import WidgetRects
from radiance_probes.scene.framing import frame_default_camera

# What a bad scene, volume or shader raises; anything else is a bug and is not swallowed.
RECOVERABLE = (SceneError, VolumeError, ShaderError, moderngl.Error, OSError, ValueError, RuntimeError)
SAVED_SCENE_NAME = "viewer_scene.json"
SNAPSHOT_MAX_PROBES = 512      # a snapshot carries the probes' coefficients for grids this small
# A mixed pool is streamed for the camera once it has not changed for this long (a drag's frames
# do not each restream: a commit restarts the accumulations and the bake).
RESTREAM_SETTLE_S = 0.3



def could_not_open(path, exc: BaseException) -> str:
    """'could not open PATH: WHY', the path said once: a loader's message starts with the path it
    failed on (as given, resolved, or its name), which the viewer's own words already name."""
    text = str(exc)
    p = Path(str(path)).expanduser()
    for prefix in sorted({str(path), str(p), str(p.resolve()), p.name}, key=len, reverse=True):
        if prefix and text.startswith(prefix + ":"):
            text = text[len(prefix) + 1:].lstrip()
            break
    return f"could not open {path}: {text}"

class Viewer:
    def __init__(self, ctx: moderngl.Context, state: ViewerState, device: str = "",
                 file_dialog: str = "auto", volume=None, settings=None, lab=None):
        self.ctx = ctx
        self.state = state
        self.device = device
        # lab: LabOptions for tests (app/rendering/lab_options.py); the launch never sets it
        self.session = RenderSession(ctx, state.scene, volume, settings=settings, lab=lab)
        self.session.bake_fills_frame = True   # a load's bake ends sooner (session._bake_budget)
        state.show_channels(self.session.volume.channel_count)
        self.widgets = WidgetRects()
        self.error_meter = ErrorMeter()
        self.files = FileDialogs(self.open_path, dialog=file_dialog)
        self.dataset_paths = datasets()
        self.timer = GpuTimer(ctx)
        self._passes: dict[str, object] = {}     # display, spheres, box: built on first use
        self._broken: set[str] = set()           # passes whose shaders failed (errors shown)
        # the probes' values the hovered probe's description reads (once per bake pass)
        self._probe_values, self._probe_values_key = None, None
        self.last_hovered_probe: dict | None = None   # the probe under the mouse last frame
        self._halted_scene = None                # the scene whose rendering raised, until it changes
        self._pending_volume = None
        self._pending_placed = None              # (shown, texture or pool) of _pending_volume
        self.opening: ProgressiveOpen | None = None   # a volume loading on a thread
        self.loading: VolumeLoading | None = None     # a file opened, read on a thread
        # a mixed pool streamed once the camera has settled (_restream)
        self._camera_seen = None
        self._camera_moved_at = 0.0
        self.input = None                        # the window's InputRouter
        self.ui_scale = 1.0
        self.window_size = (1, 1)
        self.framebuffer_size = (1, 1)
        self.screenshot_path = "screenshot.png"
        self.scene_file = SAVED_SCENE_NAME       # "save scene" never overwrites the one opened
        self.remembered_colours: dict[str, tuple] = {}
        self.environment_map_text = ""   # the light panel's map file field
        self.probe_axes_locked = len(set(state.scene.probes.grid)) == 1
        self.adaptive_strength_edit: float | None = None   # the slider's value while dragged
        self.pending_screenshot: str | None = None
        self.last_screenshot: tuple | None = None   # (path asked for, where it went, error line)
        self.close_requested = False
        self.frame_index = 0
        self._histogram = (None, None, None)
        self._last_step_at = 0.0                 # when playback last showed another step
        self._opacity_points = (None, None)
        self._drag_start = None                  # what a handle's drag moves from
        self._drag_distance = 0.0                # world units dragged so far
        self.recorder: MovieRecorder | None = None   # the movie being recorded, one frame a frame
        self.movie = MovieRecorder.default_settings()  # the panel's movie settings
        self.transfer_file = "transfer_function.json"  # the transfer-function panel's file field
        self.slices = SlicePanel(self)           # the slice view, at the window's right when on

    # ---- geometry ------------------------------------------------------------------------------
    def sidebar_width(self) -> float:
        return panels.SIDEBAR_WIDTH * self.ui_scale if self.state.show_ui else 0.0

    def view_rect_window(self) -> tuple[float, float, float, float]:
        """The picture's rectangle in window coordinates (what the cursor reports), top-left origin."""
        return layout.view_rect_window(self.window_size, self.sidebar_width(), self.slices.width())

    def view_rect_framebuffer(self) -> tuple[int, int, int, int]:
        """The same rectangle in framebuffer pixels with GL's bottom-left origin (HiDPI aware)."""
        return layout.view_rect_framebuffer(self.window_size, self.framebuffer_size,
                                            self.sidebar_width(), self.slices.width())

    def divider_x_window(self) -> float | None:
        """The split view's divider in window coordinates, None when there is no split view."""
        if self.state.display != "split" or self.state.probe_view == "alone":
            return None
        x, _, w, _ = self.view_rect_window()
        return x + self.state.split_position * w

    def render_size(self) -> tuple[int, int]:
        return layout.render_size(self.view_rect_framebuffer(), self.state.render_scale)

    def opacity_points(self):
        """The scene's opacity curve as the editor's control points (transfer.opacity_points),
        cached while the transfer function stays the same."""
        tf = self.state.transfer_function
        if self._opacity_points[0] != tf:
            self._opacity_points = (tf, opacity_points(tf))
        return self._opacity_points[1]

    def histogram(self):
        """The edited channel's histogram (of one channel, the volume's), cached."""
        volume = self.session.volume
        channel = self.edited_channel()
        if self._histogram[0] is not volume or self._histogram[2] != channel:
            self._histogram = (volume, histogram_curve(volume, channel=channel), channel)
        return self._histogram[1]

    # ---- a time series ---------------------------------------------------------------------------
    @property
    def time_steps(self) -> int:
        """Steps of the volume's time axis (1: none)."""
        return self.session.volume.time_steps

    def toggle_playing(self) -> None:
        if self.time_steps > 1:
            self.state.playing = not self.state.playing
            self._last_step_at = time.perf_counter()

    def step_time(self, delta: int) -> None:
        self.state.playing = False
        self.state.step_time(delta, self.time_steps)

    def advance_playback(self) -> None:
        """While playing, the next step once 1 / play_rate seconds have passed since the last
        (one step a frame at most: a slow frame slows the playback, it skips no step)."""
        state = self.state
        if not state.playing or self.time_steps <= 1:
            return
        now = time.perf_counter()
        if now - self._last_step_at >= 1.0 / max(state.play_rate, 1e-3):
            self._last_step_at = now
            state.step_time(+1, self.time_steps)

    def edited_channel(self) -> int:
        """Which channel of the volume the editor shows (0 for a one-channel volume)."""
        c = self.state.edited_channel
        return c if c < self.session.volume.channel_count else 0

    def edited_table(self):
        """The table the renderers use for the edited channel (of one channel, the scene's)."""
        res = self.session.renderer.resources
        return res.table if res.tables is None else res.tables.tables[self.edited_channel()]

    def edited_value_range(self) -> tuple[float, float]:
        """The data values the edited channel's densities 0 and 1 are."""
        vol = self.session.volume
        return vol.channel_ranges[self.edited_channel()] if vol.channel_ranges else vol.value_range

    # ---- actions (panels, shortcuts, scripts) --------------------------------------------------
    def run_action(self, shortcut) -> None:
        try:
            shortcut.action(self)
        except RECOVERABLE as exc:
            self.state.error(f"{shortcut.what}: {exc}")

    def request_screenshot(self, path: str | None = None) -> None:
        self.pending_screenshot = path or _free_name(self.screenshot_path)

    def request_close(self) -> None:
        self.close_requested = True

    def save_scene(self, path: str | None = None) -> Path | None:
        """Writes the scene JSON, the camera's image size set to the current render size, with
        the bookmarks and how the viewer shows it (method, view, exposure: the "viewer" key)."""
        target = Path(path or self.scene_file)
        w, h = self.render_size()
        scene = self.state.scene
        data = scene_to_dict(scene.replace(camera=replace(scene.camera, width=w, height=h),
                                           viewer=self.state.viewer_spec()))
        volume = data.get("volume", {})
        if volume.get("path") and scene.base_dir and not Path(volume["path"]).is_absolute():
            candidate = Path(scene.base_dir) / volume["path"]
            if candidate.exists():   # a file, or a TIFF or DICOM folder
                volume["path"] = str(candidate.resolve())
        env = data.get("environment")
        if isinstance(env, dict) and scene.base_dir and not Path(env["map"]).is_absolute():
            candidate = Path(scene.base_dir) / env["map"]
            if candidate.is_file():
                env["map"] = str(candidate.resolve())
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(json.dumps(data, indent=2) + "\n")
        except OSError as exc:
            self.state.error(f"could not save the scene to {target}: {exc}")
            return None
        self.state.note(f"saved the scene to {target}")
        return target

    def open_path(self, path: str) -> bool:
        """Opens a scene (.json) or a volume file; on failure the error panel says why. The file
        is read on a thread (VolumeLoading: the scene shown stays, the Data panel says how far),
        and shown once read (_poll_loading); a Zarr store read brick by brick loads on a thread
        too (open_in_background), its preview shown meanwhile."""
        try:
            scene, scene_path = scene_for_path(path, self.state.scene)
            load_scene_environment(scene)
            lazy = reads_lazily(scene)
            preview = zarr_preview(scene, memory_bytes=self.volume_memory_bytes) if lazy else None
        except RECOVERABLE as exc:
            self.state.error(could_not_open(path, exc))
            return False
        if preview is None:
            res = self.session.renderer.resources   # (a file opened before: dropped)
            self.loading = VolumeLoading(scene, scene_path, path, device_limits(self.ctx),
                                         res.volume_memory_bytes, res.brick_size)
            return True
        return self._show_opened(path, scene, scene_path, preview, preview=True)

    def _poll_loading(self) -> None:
        """Shows a file read on a thread once it is read, or says why it could not be."""
        loading = self.loading
        if loading is None or not loading.done:
            return
        self.loading = None
        try:
            volume = loading.result()
            scene = opening_scene(loading.scene, volume)   # a CT opens with its clinical preset
        except RECOVERABLE as exc:
            self.state.error(could_not_open(loading.path, exc))
            return
        self._show_opened(loading.path, scene, loading.scene_path, volume)

    def finish_loading(self) -> None:
        """Waits for a file read on a thread and shows it (scripts)."""
        if self.loading is not None:
            self.loading.wait()
            self._poll_loading()

    def _show_opened(self, path: str, scene, scene_path, volume, preview: bool = False) -> bool:
        """The scene of a file opened, framed for the view, with its volume to show."""
        _, _, w, h = self.view_rect_window()
        scene = frame_default_camera(scene, volume.half_extent, w / max(h, 1.0))
        self.state.load_scene(scene, scene_path)
        self.state.show_channels(volume.channel_count)
        self._pending_volume = volume
        self._pending_placed = None
        self.state.note(f"opened {path}")
        for note in volume.notes:
            self.state.note(note)
        if preview:
            self.open_in_background(scene)
        return True

    @property
    def volume_memory_bytes(self) -> int | None:
        return self.session.renderer.resources.volume_memory_bytes

    def open_in_background(self, scene) -> None:
        """Loads the scene's volume on a thread (app/rendering/levels/progressive_open.py) while what is
        shown now (a preview) stays; it replaces it once all its bricks are written."""
        if self.opening is not None:
            self.opening.cancel()
        res = self.session.renderer.resources
        self.opening = ProgressiveOpen(self.ctx, scene, res.volume_memory_bytes, res.brick_size,
                                       res.placement_camera(scene))

    def _poll_opening(self) -> None:
        opening = self.opening
        if opening is None:
            return
        if volume_inputs(self.state.scene) != volume_inputs(opening.scene):
            opening.cancel()
            self.opening = None
            self.state.note(f"stopped loading {opening.scene_name}: the scene's volume changed")
            return
        try:
            done = opening.poll(OPEN_WRITE_BUDGET_S)
        except RECOVERABLE as exc:
            self.opening = None
            self.state.error(could_not_open(opening.scene_name, exc))
            return
        if done is None:
            return
        given, shown, texture = done
        self.opening = None
        self._pending_volume, self._pending_placed = given, (shown, texture)
        self.state.note(f"loaded {opening.scene_name} in "
                        f"{time.perf_counter() - opening.started:.1f} s")
        for note in shown.notes:
            self.state.note(note)

    def stream_camera(self):
        """The camera a mixed pool is streamed for: the scene's, at the size rendered."""
        w, h = self.session.size
        cam = self.state.scene.camera
        return replace(cam, width=w, height=h) if w > 0 and h > 0 else cam

    def _restream(self) -> None:
        """A mixed pool (LabOptions.mixed_levels under a cap) follows the camera once it has
        settled (no camera change for RESTREAM_SETTLE_S, no button held): not on every frame of a
        drag. A restream under way goes on a budget of OPEN_WRITE_BUDGET_S a frame (the Volume
        panel shows it); a camera that settles elsewhere meanwhile starts it over."""
        stream = self.session.renderer.resources.stream
        if stream is None:
            return
        now = time.perf_counter()
        cam = self.stream_camera()
        if cam != self._camera_seen:
            self._camera_seen, self._camera_moved_at = cam, now
        settled = now - self._camera_moved_at >= RESTREAM_SETTLE_S and not self._mouse_held()
        target = cam if settled else (stream.pending.camera if stream.pending else None)
        if target is None or (stream.pending is None and target == stream.camera):
            return
        try:
            self.session.restream(target, OPEN_WRITE_BUDGET_S)
        except RECOVERABLE as exc:
            stream.cancel()
            self.state.error(f"streaming the finer level: {exc}")

    def stream_wanted(self) -> bool:
        """Whether a mixed pool has work for the camera: a restream under way, or a camera it
        has not been streamed for (done once the camera settles)."""
        stream = self.session.renderer.resources.stream
        return stream is not None and (stream.pending is not None
                                       or stream.camera != self.stream_camera())

    def finish_streaming(self) -> None:
        """Completes a restream for the current camera (scripted runs, screenshots)."""
        if self.session.renderer.resources.stream is not None:
            self.session.restream(self.stream_camera())

    def finish_opening(self) -> None:
        """Waits for a volume loading on a thread and shows it (scripted runs, screenshots)."""
        while self.opening is not None:
            self._poll_opening()
            if self.opening is not None:
                time.sleep(0.005)

    # ---- the crop box's and clip plane's handles -------------------------------------------------
    def world_to_window(self, points) -> np.ndarray:
        """World points (k, 3) as window coordinates (what the cursor reports), (k, 2)."""
        w, h = self.session.size
        if w <= 0 or h <= 0:
            return np.zeros((0, 2))
        pixels = orbit.project(self.view_projection(), np.asarray(points, np.float64).reshape(-1, 3),
                               w, h)
        x0, y0, rw, rh = self.view_rect_window()
        return np.stack([x0 + pixels[:, 0] / w * rw, y0 + pixels[:, 1] / h * rh], axis=1)

    def handle_points(self) -> list[tuple]:
        """(handle, window position) of every handle shown."""
        if not self.state.show_handles:
            return []
        marks = crop_handles.handles(self.state.scene, self.session.volume)
        if not marks:
            return []
        where = self.world_to_window([m.position for m in marks])
        return list(zip(marks, map(tuple, where.tolist())))

    def handle_at(self, x: float, y: float):
        """The handle under the cursor (within GRAB_PIXELS), its drag begun; None if none."""
        best, best_d = None, crop_handles.GRAB_PIXELS
        for mark, (hx, hy) in self.handle_points():
            d = float(np.hypot(hx - x, hy - y))
            if d <= best_d:
                best, best_d = mark, d
        if best is not None:
            self._drag_start = crop_handles.drag_start(self.state.scene, best)
            self._drag_distance = 0.0
        return best

    def drag_handle(self, mark, dx: float, dy: float) -> None:
        """Moves a handle by a cursor move (window pixels): the part of it along the handle's
        direction as the view shows that direction."""
        p0 = np.asarray(mark.position, np.float64)
        ends = self.world_to_window([p0, p0 + 0.1 * np.asarray(mark.direction)])
        screen = (ends[1] - ends[0]) / 0.1            # window pixels per world unit along it
        length2 = float(screen @ screen)
        if length2 < 1e-6 or self._drag_start is None:
            return                                    # seen end-on: a drag cannot say how far
        self._drag_distance += float(np.array([dx, dy]) @ screen) / length2
        try:
            self.state.scene = crop_handles.dragged(self.state.scene, self.session.volume, mark,
                                                    self._drag_start, self._drag_distance)
        except RECOVERABLE as exc:
            self.state.error(f"crop: {exc}")

    # ---- movies --------------------------------------------------------------------------------
    def toggle_recording(self) -> None:
        """Starts recording the movie the panel sets up, or stops the one under way."""
        if self.recorder is not None:
            path = self.recorder.stop()
            self.recorder = None
            self.state.note(f"stopped recording ({path} holds what was recorded)")
            return
        try:
            self.recorder = MovieRecorder(self.session.renderer, self.state.scene,
                                          self.session.volume, self.movie)
        except RECOVERABLE as exc:
            self.state.error(f"movie: {exc}")
            return
        self.state.note(f"recording {self.recorder.total} frames to {self.movie['out']}")

    def _record_step(self) -> None:
        if self.recorder is None:
            return
        try:
            done = self.recorder.step()
        except RECOVERABLE as exc:
            self.state.error(f"movie: {exc}")
            self.recorder.stop()
            self.recorder = None
            return
        if done:
            self.state.note(self.recorder.finish_note())
            self.recorder = None

    def open_builtin(self, name: str) -> None:
        size = self.state.scene.volume.size if self.state.scene.volume.path is None else (64, 64, 64)
        self.state.load_scene(builtin_scene(name, size, self.state.scene))

    # ---- one frame -----------------------------------------------------------------------------
    def apply_input(self) -> None:
        if self.input is not None:
            (ox, oy), (px, py), zoom_steps = self.input.take_camera_moves()
            cam = self.state.scene.camera
            if ox or oy:
                cam = orbit.orbit(cam, ox, oy)
            if px or py:
                cam = orbit.pan(cam, px, py, self.view_rect_window()[3])
            if zoom_steps:
                cam = orbit.zoom(cam, zoom_steps)
            if cam is not self.state.scene.camera:
                self.state.set_camera(cam)
            if self.input.divider_x is not None:
                x, _, w, _ = self.view_rect_window()
                self.state.split_position = float(np.clip((self.input.divider_x - x) / w, 0.0, 1.0))
                self.input.divider_x = None
            for path in self.input.take_dropped():
                self.open_path(path)
        self.files.poll()

    def _sync(self) -> None:
        """Hands the edited scene to the renderers; a scene that fails is reverted and reported."""
        state = self.state
        volume, self._pending_volume = self._pending_volume, None
        placed, self._pending_placed = self._pending_placed, None
        try:
            self.session.set_scene(state.scene, volume, placed)
        except RECOVERABLE as exc:
            if placed is not None:
                placed[1].release()
            state.error(f"could not apply the scene: {exc}")
            state.scene = self.session.scene
        self.session.set_filter(linear=state.render_scale < 1.0)
        self.session.resize(*self.render_size())
        self.session.set_methods(state.shown_methods())

    def render_frame(self) -> FrameTimes:
        """Advances the renderers and draws the picture into the window's framebuffer."""
        state = self.state
        self.advance_playback()
        state.history.observe(state.scene, busy=self._mouse_held())
        self._poll_loading()
        self._poll_opening()
        self._sync()
        self._restream()
        self._record_step()
        times = FrameTimes()
        if self._halted_scene is not None and self._halted_scene is not state.scene:
            self._halted_scene = None
        if self._halted_scene is None:
            try:
                times = self.session.step(state.max_samples, state.wants_probes())
            except RECOVERABLE as exc:
                state.error(f"rendering stopped: {exc}")
                self._halted_scene = state.scene
        if state.display == "error" and state.method != REFERENCE:
            self.error_meter.update(self.session, state.method, state.max_samples)
        self.ctx.screen.use()
        self.ctx.viewport = (0, 0, *self.framebuffer_size)
        self.ctx.clear(*BACKGROUND, 1.0, depth=1.0)
        t = time.perf_counter()
        self.timer.start()
        self._draw_picture()
        self.timer.stop()
        times.display_ms = self.timer.elapsed_ms
        self.session.parts.add("display", 1e3 * (time.perf_counter() - t), times.display_ms)
        self.session.last = times
        self.session.record_frame(times)
        error = self.ctx.error
        if error != "GL_NO_ERROR":
            state.error(f"OpenGL error {error} in frame {self.frame_index}")
        self.frame_index += 1
        return times

    def _draw_picture(self) -> None:
        state, session = self.state, self.session
        rect = self.view_rect_framebuffer()
        display = self._pass("display", DisplayPass)
        if display is not None:
            main = session.texture(state.method) if state.probe_view != "alone" else None
            other = None
            if state.display == "split":
                other = session.texture(state.split_method)
            elif state.display == "error" and state.method != REFERENCE:
                other = session.texture(REFERENCE)
            mode = (state.display if (state.display != "error" or state.method != REFERENCE)
                    else "image")
            if state.probe_view == "alone":
                mode = "image"
            rms = self.error_meter.reference_rms
            display.draw(rect, mode, main, other, state.split_position, state.exposure,
                         1.0 / (state.heat_max * rms) if rms > 0 else 0.0)
        matrix = self.view_projection()
        grid = session.probe_grid
        if state.probe_view != "off" and grid is not None and grid.passes_done > 0:
            spheres = self._pass("spheres", ProbeSpheres)
            if spheres is not None:
                self.ctx.viewport = rect
                spheres.draw(matrix, grid, session.renderer.resources, state.exposure,
                             self.probe_slab())
        if state.show_box:
            box = self._pass("box", BoxOutline)
            if box is not None:
                self.ctx.viewport = rect
                box.draw(matrix, session.volume.half_extent)
        if state.slice_view != "off":
            images = self._pass("slices", SliceImages)
            if images is not None:
                self.slices.render(images)

    def _mouse_held(self) -> bool:
        """A mouse button down (a drag under way: a slider, a curve point, a handle)."""
        if self.input is not None and self.input.drag is not None:
            return True
        try:
            from imgui_bundle import imgui
            return any(imgui.is_mouse_down(b) for b in range(3))
        except Exception:   # no ImGui frame yet
            return False

    def _pass(self, name: str, cls):
        """A drawing pass, built on first use; a shader that fails is reported once and skipped."""
        if name in self._passes:
            return self._passes[name]
        if name in self._broken:
            return None
        try:
            self._passes[name] = cls(self.ctx)
        except (ShaderError, moderngl.Error) as exc:
            self._broken.add(name)
            self.state.error(f"the {name} pass is off: {exc}")
            return None
        return self._passes[name]

    def view_projection(self) -> np.ndarray:
        w, h = self.session.size
        return orbit.view_projection(camera_frame(self.state.scene.camera, w, h))

    def build_ui(self) -> None:
        """The ImGui panels of this frame (between imgui.new_frame and imgui.render)."""
        self.widgets.begin_frame()
        if self.state.show_ui:
            panels.sidebar(self)
        overlays.view_labels(self)
        self.slices.draw()
        overlays.crop_overlay(self)
        overlays.probe_tooltip(self)
        overlays.help_window(self)
        overlays.file_browser(self)
        overlays.error_window(self)
        self.widgets.end_frame()

    # ---- for scripts and tests -----------------------------------------------------------------
    def probe_pixels(self) -> list[list[float]]:
        """Where each probe centre lands in a screenshot (framebuffer pixels, top-left origin)."""
        grid = self.session.probe_grid
        if grid is None:
            return []
        w, h = self.session.size
        centres = probe_centres(grid.grid, self.session.volume.half_extent, grid.box, grid.planes)
        pixels = orbit.project(self.view_projection(), centres, w, h)
        x0, _, rw, rh = self.view_rect_framebuffer()
        top = self.framebuffer_size[1] - rh
        return [[x0 + px / w * rw, top + py / h * rh] for px, py in pixels.tolist()]

    def probe_slab(self) -> tuple[str, int] | None:
        """The probe view's slab (axis, plane index), None for the whole grid."""
        grid = self.session.probe_grid
        if self.state.probe_slab_axis == "all" or grid is None:
            return None
        axis = self.state.probe_slab_axis
        return axis, slab_plane(grid.grid, axis, self.state.probe_slab)

    def hovered_probe(self, mouse) -> dict | None:
        """The probe drawn under the mouse (window coordinates) and what it holds: its index and
        describe_probe's lines; None where no drawn probe is there. The probes' values are read
        back once per bake pass."""
        spheres = self._passes.get("spheres")
        grid = self.session.probe_grid
        if (self.state.probe_view == "off" or spheres is None or spheres.selection is None
                or grid is None or len(spheres.centres_drawn) == 0):
            return None
        x, y, rw, rh = self.view_rect_window()
        if not (x <= mouse[0] < x + rw and y <= mouse[1] < y + rh):
            return None
        w, h = self.session.size
        pixel = ((mouse[0] - x) / rw * w, (mouse[1] - y) / rh * h)
        hit = probe_under(pixel, spheres.centres_drawn, self.view_projection(), w, h,
                          spheres.radius, self.state.scene.camera.eye)
        if hit is None:
            return None
        index = int(spheres.selection.indices[hit])
        key = (id(grid), grid.passes_done)
        if self._probe_values_key != key:
            self._probe_values = grid.coefficients().reshape(grid.count, -1)
            self._probe_values_key = key
        return {"index": index,
                "lines": describe_probe(index, grid.grid, spheres.centres_drawn[hit],
                                        self._probe_values[index], grid.sh_order)}

    def probes_drawn(self) -> dict | None:
        """Which probes the probe-grid view draws (ProbeSelection), None while it draws none."""
        spheres = self._passes.get("spheres")
        selection = None if spheres is None else spheres.selection
        if self.state.probe_view == "off" or selection is None:
            return None
        return {"indices": selection.indices.tolist(), "stride": selection.stride,
                "visible": selection.visible, "total": selection.total,
                "slab": list(self.probe_slab()) if self.probe_slab() is not None else None}

    def snapshot(self) -> dict:
        """The state a test asserts on, JSON-ready."""
        s, session = self.state, self.session
        grid = session.probe_grid
        return {
            "frame": self.frame_index, "method": s.method, "display": s.display,
            "split_method": s.split_method, "split_position": s.split_position,
            "probe_view": s.probe_view, "show_box": s.show_box, "exposure": s.exposure,
            "show_ui": s.show_ui, "show_help": s.show_help, "scene_path": s.scene_path,
            "scene": scene_to_dict(s.scene),
            "samples": {m: session.samples(m) for m in session.views},
            "labels": {m: session.label(m) for m in session.views},
            "refine": session.refine_state(),
            "restarts": session.restarts,
            "render_size": list(session.size), "framebuffer_size": list(self.framebuffer_size),
            "window_size": list(self.window_size), "view_rect_window": list(self.view_rect_window()),
            "view_rect_framebuffer": list(self.view_rect_framebuffer()),
            "bake_passes_run": session.bake_passes_run, "bakes_started": session.bake_generation,
            "empty_space_skipping": session.renderer.resources.use_majorant_grid,
            "gather_event": session.renderer.probe_gather_event,
            "settings": session.renderer.settings.as_dict(),
            "probes_ready": session.probes_ready(),
            "probe_grid": list(grid.grid) if grid is not None else None,
            "probe_box": grid.box if grid is not None else None,
            "probe_planes": grid.planes if grid is not None else None,
            "probe_sh_order": grid.sh_order if grid is not None else None,
            "probe_bytes": grid.gpu_bytes if grid is not None else 0,
            "bake_ms": session.bake_ms, "frame_ms": session.last.total_ms,
            "clock": session.pacer.clock, "frame_wall_ms": session.pacer.frame_ms,
            "frame_parts": {k: list(v) for k, v in session.parts.last.items()},
            "rel_rmse": self.error_meter.value if s.display == "error" else None,
            "probe_pixels": self.probe_pixels() if s.probe_view != "off" else [],
            "probes_drawn": self.probes_drawn(),
            "probe_hovered": self.last_hovered_probe,
            "probe_coefficients": (grid.coefficients().reshape(grid.count, -1).tolist()
                                   if grid is not None and grid.count <= SNAPSHOT_MAX_PROBES
                                   and s.probe_view != "off" else None),
            "camera_eye": list(s.scene.camera.eye),
            "half_extent": [float(x) for x in session.volume.half_extent],
            "volume": {"name": session.volume.name, "dims": list(session.volume.dims),
                       **({"time": session.volume.time, "time_steps": session.volume.time_steps}
                          if session.volume.time_steps > 1 else {}),
                       **({"channels": session.volume.channel_count}
                          if session.volume.channel_count > 1 else {})},
            "dicom_series": (session.volume.dicom_series.number
                             if session.volume.dicom_series is not None else None),
            "volume_notes": list(session.volume.notes),
            "opening": None if self.opening is None else self.opening.progress(),
            "loading": None if self.loading is None else self.loading.progress(),
            "streaming": self._stream_snapshot(),
            "playing": s.playing,
            "opacity_points": [list(p) for p in self.opacity_points()[0]],
            "clip_region": (None if session.renderer.resources.clip is None else
                            {"box_min": list(session.renderer.resources.clip.box_min),
                             "box_max": list(session.renderer.resources.clip.box_max),
                             "plane": list(session.renderer.resources.clip.plane)}),
            "handles": {m.name: list(p) for m, p in self.handle_points()},
            "slices": self.slices.snapshot(),
            "undo_steps": len(s.history.undo_steps), "redo_steps": len(s.history.redo_steps),
            "recording": None if self.recorder is None else self.recorder.progress(),
            "errors": list(s.errors), "messages": list(s.messages),
            "widgets": {k: list(v) for k, v in self.widgets.rects.items()},
        }

    def _stream_snapshot(self) -> dict | None:
        stream = self.session.renderer.resources.stream
        if stream is None:
            return None
        return {"status": stream.status(), "resident": stream.resident, "loaded": stream.loaded,
                "evicted": stream.evicted, "commits": stream.commits,
                "slots": stream.mix.f_slots, "wanted": self.stream_wanted()}

    def release(self) -> None:
        if self.opening is not None:
            self.opening.cancel()
            self.opening = None
        for p in self._passes.values():
            p.release()
        self._passes.clear()
        self.slices.release()
        self.timer.release()
        self.session.release()


def _free_name(path: str) -> str:
    p = Path(path)
    if not p.exists():
        return str(p)
    i = 1
    while (candidate := p.with_name(f"{p.stem}_{i:03d}{p.suffix}")).exists():
        i += 1
    return str(candidate)
