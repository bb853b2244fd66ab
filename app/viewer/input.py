"""Mouse and keyboard: the GLFW callbacks. Each event goes to Dear ImGui's GLFW backend first and
then, unless ImGui wants it (a widget under the cursor, a text field with focus), to the viewer:
orbit on left drag, pan on right or middle drag, zoom on the wheel, keyboard shortcuts, dropped
files. Scripts and tests call these same methods with synthetic events."""
from __future__ import annotations

import ctypes
from dataclasses import dataclass
from typing import Callable

from imgui_bundle import imgui

from radiance_probes.methods import METHODS
from radiance_probes.viewer.glfw_lib import glfw

from radiance_probes.viewer.slice_view import SLICE_VIEWS
from radiance_probes.viewer.state import PROBE_VIEWS


@dataclass(frozen=True)
class Shortcut:
    keys: str                       # as shown in the help panel and accepted by scripts
    what: str
    action: Callable                # action(viewer)
    listed: bool = True             # in the help table itself (a family: one line in GROUP_HELP)


def _method(name: str) -> Callable:
    return lambda v: v.state.set_method(name)


SHORTCUTS = (
    *(Shortcut(m.viewer_key, f"method: {m.name} ({m.doc})", _method(m.name))
      for m in METHODS.values() if m.viewer_key is not None),   # the registry's keys
    Shortcut("s", "split view on/off (method | split method)", lambda v: v.state.toggle_display("split")),
    Shortcut("e", "error view on/off (heat map against pt)", lambda v: v.state.toggle_display("error")),
    Shortcut("g", "probe grid: off, over the volume, alone", lambda v: v.state.cycle("probe_view", PROBE_VIEWS)),
    Shortcut("v", "slice view: off, three slices, the x, y or z slice alone",
             lambda v: v.state.cycle("slice_view", SLICE_VIEWS)),
    Shortcut("b", "volume box on/off", lambda v: setattr(v.state, "show_box", not v.state.show_box)),
    Shortcut("]", "probe grid finer", lambda v: v.state.step_probe_grid(+1)),
    Shortcut("[", "probe grid coarser", lambda v: v.state.step_probe_grid(-1)),
    Shortcut("left", "sun azimuth -15 deg", lambda v: v.state.turn_light(-15, 0)),
    Shortcut("right", "sun azimuth +15 deg", lambda v: v.state.turn_light(15, 0)),
    Shortcut("up", "sun elevation +10 deg", lambda v: v.state.turn_light(0, 10)),
    Shortcut("down", "sun elevation -10 deg", lambda v: v.state.turn_light(0, -10)),
    Shortcut("c", "next colormap", lambda v: v.state.cycle_colormap(+1)),
    Shortcut("=", "exposure x1.25", lambda v: setattr(v.state, "exposure", v.state.exposure * 1.25)),
    Shortcut("-", "exposure /1.25", lambda v: setattr(v.state, "exposure", v.state.exposure / 1.25)),
    Shortcut("r", "reset camera", lambda v: v.state.reset_camera()),
    Shortcut("tab", "hide/show the panels", lambda v: setattr(v.state, "show_ui", not v.state.show_ui)),
    Shortcut("f1", "help on/off", lambda v: setattr(v.state, "show_help", not v.state.show_help)),
    Shortcut("f12", "save a screenshot (PNG, with the panels)", lambda v: v.request_screenshot()),
    Shortcut("x", "crop box and clip plane on/off (a crop box to drag when there is none)",
             lambda v: v.state.toggle_clipping(v.session.volume.dims)),
    Shortcut("h", "crop and clip handles on/off", lambda v: setattr(v.state, "show_handles",
                                                                    not v.state.show_handles)),
    Shortcut("space", "time series: play / pause", lambda v: v.toggle_playing()),
    Shortcut(".", "time series: next step", lambda v: v.step_time(+1)),
    Shortcut(",", "time series: previous step", lambda v: v.step_time(-1)),
    Shortcut("ctrl+z", "undo the last scene edit", lambda v: v.state.undo()),
    Shortcut("ctrl+y", "redo", lambda v: v.state.redo()),
    Shortcut("ctrl+shift+z", "redo", lambda v: v.state.redo()),
    Shortcut("ctrl+r", "record the movie set in 'Bookmarks and movie' (again: stop)",
             lambda v: v.toggle_recording()),
    *(Shortcut(f"ctrl+{n}", f"save the view as bookmark {n}",
               (lambda k: lambda v: v.state.save_bookmark(k))(n), listed=False) for n in range(1, 10)),
    *(Shortcut(f"shift+{n}", f"go to bookmark {n}",
               (lambda k: lambda v: v.state.go_to_bookmark(k))(n), listed=False) for n in range(1, 10)),
    Shortcut("ctrl+s", "save the scene JSON (with bookmarks and how the viewer shows it)",
             lambda v: v.save_scene()),
    Shortcut("ctrl+o", "open a scene or volume file", lambda v: v.files.open_dialog()),
    Shortcut("ctrl+q", "quit", lambda v: v.request_close()),
)
GROUP_HELP = (("ctrl+1 .. ctrl+9", "save the view as bookmark N"),
              ("shift+1 .. shift+9", "go to bookmark N"))
MOUSE_HELP = (("left drag", "orbit (on a crop or clip handle: move that face or the plane)"), ("right or middle drag", "pan"), ("wheel", "zoom"),
              ("click in a slice", "the slices and the orbit's centre to that voxel (the wheel "
                                   "steps the slice)"),
              ("drop a file", "open a scene (.json), a volume (.raw, .nrrd, .npy, .nii, .nii.gz, .tif) "
                               "or a folder (TIFF stack, DICOM series)"))

_NAMED_KEYS = {
    "left": glfw.KEY_LEFT, "right": glfw.KEY_RIGHT, "up": glfw.KEY_UP, "down": glfw.KEY_DOWN,
    "tab": glfw.KEY_TAB, "escape": glfw.KEY_ESCAPE, "space": glfw.KEY_SPACE,
    "enter": glfw.KEY_ENTER, "[": glfw.KEY_LEFT_BRACKET, "]": glfw.KEY_RIGHT_BRACKET,
    "=": glfw.KEY_EQUAL, "-": glfw.KEY_MINUS, "+": glfw.KEY_KP_ADD,
    ",": glfw.KEY_COMMA, ".": glfw.KEY_PERIOD,
    **{f"f{i}": getattr(glfw, f"KEY_F{i}") for i in range(1, 13)},
    **{c: getattr(glfw, f"KEY_{c.upper()}") for c in "abcdefghijklmnopqrstuvwxyz0123456789"},
}
_ALIASES = {glfw.KEY_KP_ADD: glfw.KEY_EQUAL, glfw.KEY_KP_SUBTRACT: glfw.KEY_MINUS,
            **{getattr(glfw, f"KEY_KP_{i}"): getattr(glfw, f"KEY_{i}") for i in range(10)}}
_MODS = {"ctrl": glfw.MOD_CONTROL, "shift": glfw.MOD_SHIFT, "alt": glfw.MOD_ALT}


def parse_keys(text: str) -> tuple[int, int]:
    """'ctrl+s' -> (glfw.KEY_S, glfw.MOD_CONTROL)."""
    *mods, name = text.lower().split("+") if text != "+" else ["+"]
    if name not in _NAMED_KEYS or any(m not in _MODS for m in mods):
        raise ValueError(f"unknown key {text!r}")
    mask = 0
    for m in mods:
        mask |= _MODS[m]
    return _NAMED_KEYS[name], mask


_BINDINGS = {parse_keys(s.keys): s for s in SHORTCUTS}


DIVIDER_GRAB_PIXELS = 6.0


@dataclass
class Drag:
    button: int
    kind: str          # orbit, pan, divider, handle or slice
    handle: object = None   # the crop or clip handle being dragged (crop_handles.Handle)


class InputRouter:
    """The GLFW callbacks of one window; ``viewer`` supplies the view rectangle and the actions."""

    def __init__(self, window, viewer):
        self.window = window
        self.address = ctypes.cast(window, ctypes.c_void_p).value
        self.viewer = viewer
        self.cursor = (0.0, 0.0)
        self.drag: Drag | None = None
        self.orbit_pixels = [0.0, 0.0]   # pending since the last frame, window coordinates
        self.pan_pixels = [0.0, 0.0]
        self.zoom_steps = 0.0
        self.divider_x: float | None = None  # where the split view's divider was dragged to
        self.dropped: list[str] = []
        self.real_input = True             # scripts turn the window system's events off

    def install(self) -> None:
        w = self.window
        for setter, handler in ((glfw.set_key_callback, self.on_key),
                                (glfw.set_char_callback, self.on_char),
                                (glfw.set_mouse_button_callback, self.on_mouse_button),
                                (glfw.set_cursor_pos_callback, self.on_cursor_pos),
                                (glfw.set_scroll_callback, self.on_scroll),
                                (glfw.set_cursor_enter_callback, self.on_cursor_enter),
                                (glfw.set_window_focus_callback, self.on_focus),
                                (glfw.set_drop_callback, self.on_drop)):
            setter(w, self._from_glfw(handler))

    def _from_glfw(self, handler):
        """The handler as GLFW calls it; muted while a script owns the input, so that the X
        server's own pointer (Xvfb's sits in the middle of the screen) cannot interfere."""
        def callback(*args):
            if self.real_input:
                handler(*args)
        return callback

    # ---- callbacks (GLFW's signatures) ---------------------------------------------------------
    def on_focus(self, window, focused) -> None:
        imgui.backends.glfw_window_focus_callback(self.address, int(focused))

    def on_cursor_enter(self, window, entered) -> None:
        imgui.backends.glfw_cursor_enter_callback(self.address, int(entered))

    def on_cursor_pos(self, window, x: float, y: float) -> None:
        imgui.backends.glfw_cursor_pos_callback(self.address, float(x), float(y))
        dx, dy = x - self.cursor[0], y - self.cursor[1]
        self.cursor = (float(x), float(y))
        if self.drag is None:
            return
        if self.drag.kind == "divider":
            self.divider_x = float(x)
            return
        if self.drag.kind == "handle":
            self.viewer.drag_handle(self.drag.handle, dx, dy)
            return
        if self.drag.kind == "slice":
            self.viewer.slices.pick(float(x), float(y))
            return
        target = self.orbit_pixels if self.drag.kind == "orbit" else self.pan_pixels
        target[0] += dx
        target[1] += dy

    def on_mouse_button(self, window, button: int, action: int, mods: int) -> None:
        imgui.backends.glfw_mouse_button_callback(self.address, button, action, mods)
        if (action == glfw.PRESS and self.drag is None and button == glfw.MOUSE_BUTTON_LEFT
                and not imgui.get_io().want_capture_mouse and self.viewer.slices.pick(*self.cursor)):
            self.drag = Drag(button, "slice")
        elif action == glfw.PRESS and self.drag is None and self._over_view():
            divider = self.viewer.divider_x_window()
            handle = (self.viewer.handle_at(*self.cursor) if button == glfw.MOUSE_BUTTON_LEFT
                      else None)
            if handle is not None:
                self.drag = Drag(button, "handle", handle)
            elif button == glfw.MOUSE_BUTTON_LEFT and divider is not None \
                    and abs(self.cursor[0] - divider) <= DIVIDER_GRAB_PIXELS:
                self.drag = Drag(button, "divider")
            else:
                self.drag = Drag(button, "orbit" if button == glfw.MOUSE_BUTTON_LEFT else "pan")
        elif action == glfw.RELEASE and self.drag is not None and self.drag.button == button:
            self.drag = None

    def on_scroll(self, window, dx: float, dy: float) -> None:
        imgui.backends.glfw_scroll_callback(self.address, float(dx), float(dy))
        if self._over_view():
            self.zoom_steps += dy
        elif not imgui.get_io().want_capture_mouse:
            self.viewer.slices.scroll(*self.cursor, float(dy))

    def on_key(self, window, key: int, scancode: int, action: int, mods: int) -> None:
        imgui.backends.glfw_key_callback(self.address, key, scancode, action, mods)
        if action not in (glfw.PRESS, glfw.REPEAT):
            return
        io = imgui.get_io()
        if io.want_text_input or (io.want_capture_keyboard and not mods & glfw.MOD_CONTROL):
            return
        mods &= glfw.MOD_CONTROL | glfw.MOD_SHIFT | glfw.MOD_ALT
        key = _ALIASES.get(key, key)
        shortcut = _BINDINGS.get((key, mods)) or _BINDINGS.get((key, mods & ~glfw.MOD_SHIFT))
        if shortcut is not None:
            self.viewer.run_action(shortcut)

    def on_char(self, window, codepoint: int) -> None:
        imgui.backends.glfw_char_callback(self.address, codepoint)

    def on_drop(self, window, paths) -> None:
        self.dropped.extend(str(p) for p in paths)

    # ---- the viewer takes what piled up since the last frame ------------------------------------
    def _over_view(self) -> bool:
        if imgui.get_io().want_capture_mouse:
            return False
        x, y, w, h = self.viewer.view_rect_window()
        return x <= self.cursor[0] < x + w and y <= self.cursor[1] < y + h

    def take_camera_moves(self) -> tuple[tuple[float, float], tuple[float, float], float]:
        moves = (tuple(self.orbit_pixels), tuple(self.pan_pixels), self.zoom_steps)
        self.orbit_pixels, self.pan_pixels, self.zoom_steps = [0.0, 0.0], [0.0, 0.0], 0.0
        return moves

    def take_dropped(self) -> list[str]:
        paths, self.dropped = self.dropped, []
        return paths
