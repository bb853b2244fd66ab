"""Scripts: a JSON list of steps that drive the real viewer through its own input callbacks (the
ones GLFW calls), frame by frame, and save screenshots and state dumps. Tests and the screenshot
script use them; a person can too (``view SCENE --script steps.json``).

Steps (one key each; positions are window coordinates, a widget's name, {"view": [fx, fy]},
fractions of the picture's rectangle, or {"slice": "x" | "y" | "z", "at": [fx, fy]}, fractions of
that slice's image in the slice view):
  {"frames": N}                      render N frames
  {"until": "baked" | "done" | "loaded", "max_frames": M}   frames until the probes are baked /
                                     nothing is left to render (the scripted --spp cap reached) /
                                     a volume loading on a thread is shown
  {"key": "s"} / {"key": "ctrl+s"}   press and release a key (see input.SHORTCUTS)
  {"click": TARGET, "button": "left"}
  {"double_click": TARGET}
  {"drag": TARGET, "to": TARGET | "by": [dx, dy], "button": "left", "steps": 6}
  {"scroll": TARGET, "steps": 1}     mouse wheel notches (positive zooms in)
  {"move": TARGET}                   move the mouse there (hover), then one frame
  {"resize": [W, H]}                 resize the window
  {"drop": [PATH, ...]}              drop files on the window
  {"screenshot": PATH}               save the window's image (panels included) after one frame
  {"dump": PATH}                     write the viewer's state as JSON (Viewer.snapshot)
  {"close": true}                    close the window as its close button does
A step that opened a file (read on a thread, app/viewer/opening.py) waits for it and draws one
frame more, which shows it, unless it says "wait": false (then {"until": "loaded"} waits).
"""
from __future__ import annotations

import json
from pathlib import Path

from imgui_bundle import imgui

from radiance_probes.viewer.glfw_lib import glfw
from radiance_probes.viewer.input import parse_keys

BUTTONS = {"left": glfw.MOUSE_BUTTON_LEFT, "right": glfw.MOUSE_BUTTON_RIGHT,
           "middle": glfw.MOUSE_BUTTON_MIDDLE}
DEFAULT_MAX_FRAMES = 3000
SCROLL_TO_WIDGET_TRIES = 40


class ScriptError(RuntimeError):
    pass


def load_script(path: str | Path) -> list[dict]:
    try:
        steps = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise ScriptError(f"{path}: cannot read the script ({exc})") from None
    if not isinstance(steps, list) or not all(isinstance(s, dict) for s in steps):
        raise ScriptError(f"{path}: a script is a JSON list of objects")
    return steps


class ScriptRunner:
    def __init__(self, window, base_dir: str | Path = "."):
        self.window = window
        self.viewer = window.viewer
        self.input = window.input
        self.handle = window.window
        self.base_dir = Path(base_dir)

    def frame(self, n: int = 1) -> None:
        for _ in range(n):
            if self.window.should_close():
                return
            self.window.poll()
            self.window.frame()

    def run(self, steps: list[dict]) -> None:
        self.input.real_input = False
        self.input.on_cursor_enter(self.handle, 1)
        self.frame()
        for i, step in enumerate(steps):
            if self.window.should_close():
                break
            loading = self.viewer.loading
            try:
                self.step(step)
            except (KeyError, ValueError, TypeError) as exc:
                raise ScriptError(f"step {i} {json.dumps(step)}: {exc}") from None
            opened = self.viewer.loading is not None and self.viewer.loading is not loading
            if opened and step.get("wait", True):
                self.viewer.finish_loading()   # a file the step opened: shown from this frame
                self.frame()

    def _path(self, p: str) -> Path:
        path = Path(p)
        return path if path.is_absolute() else self.base_dir / path

    # ---- steps ---------------------------------------------------------------------------------
    def step(self, s: dict) -> None:
        if "frames" in s:
            self.frame(int(s["frames"]))
        elif "until" in s:
            self.until(s["until"], int(s.get("max_frames", DEFAULT_MAX_FRAMES)))
        elif "key" in s:
            self.key(s["key"])
        elif "click" in s:
            self.click(s["click"], BUTTONS[s.get("button", "left")])
        elif "double_click" in s:
            self.click(s["double_click"], glfw.MOUSE_BUTTON_LEFT, double=True)
        elif "drag" in s:
            self.drag(s["drag"], s.get("to"), s.get("by"), BUTTONS[s.get("button", "left")],
                      int(s.get("steps", 6)))
        elif "move" in s:
            self.move(self.position(s["move"]))
        elif "scroll" in s:
            self.move(self.position(s["scroll"]))
            self.input.on_scroll(self.handle, 0.0, float(s.get("steps", 1)))
            self.frame()
        elif "resize" in s:
            self.resize(*s["resize"])
        elif "drop" in s:
            self.input.on_drop(self.handle, [str(self._path(p)) for p in s["drop"]])
            self.frame()
        elif "screenshot" in s:
            self.viewer.request_screenshot(str(self._path(s["screenshot"])))
            self.frame()
        elif "dump" in s:
            path = self._path(s["dump"])
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(self.viewer.snapshot(), indent=1))
        elif "close" in s:
            glfw.set_window_should_close(self.handle, True)
        else:
            raise ValueError("unknown step")

    def until(self, condition: str, max_frames: int) -> None:
        v = self.viewer
        checks = {"baked": lambda: v.session.probes_ready(),
                  "done": lambda: v.session.finished(v.state.max_samples, v.state.wants_probes()),
                  "loaded": lambda: v.opening is None and v.loading is None,
                  "streamed": lambda: not v.stream_wanted()}
        if condition not in checks:
            raise ValueError(f"unknown condition {condition!r} (known: {', '.join(checks)})")
        for _ in range(max_frames):
            self.frame()
            if checks[condition]():
                return
        raise ScriptError(f"'{condition}' not reached in {max_frames} frames")

    def key(self, name: str) -> None:
        key, mods = parse_keys(name)
        self.input.on_key(self.handle, key, 0, glfw.PRESS, mods)
        if len(name) == 1 and not mods:
            self.input.on_char(self.handle, ord(name))
        self.frame()
        self.input.on_key(self.handle, key, 0, glfw.RELEASE, mods)
        self.frame()

    def position(self, target) -> tuple[float, float]:
        if isinstance(target, str):
            self._scroll_into_view(target)
            return self.viewer.widgets.centre(target)
        if isinstance(target, dict) and "slice" in target:
            x, y, w, h = self.viewer.slices.image_rect(target["slice"])
            fx, fy = target.get("at", (0.5, 0.5))
            return x + fx * w, y + fy * h
        if isinstance(target, dict) and "view" in target:
            x, y, w, h = self.viewer.view_rect_window()
            fx, fy = target["view"]
            return x + fx * w, y + fy * h
        x, y = target
        return float(x), float(y)

    def _scroll_into_view(self, name: str) -> None:
        """Scrolls the sidebar with the wheel until the widget is inside the window."""
        for _ in range(SCROLL_TO_WIDGET_TRIES):
            rect = self.viewer.widgets.rects.get(name)
            height = self.viewer.window_size[1]
            if rect is not None and rect[1] >= 0 and rect[3] <= height:
                return
            if rect is None and not self.viewer.widgets.rects:
                self.frame()
                continue
            self.move((self.viewer.sidebar_width() / 2, height / 2))
            notches = 1.0 if rect is None or rect[1] < 0 else -1.0
            self.input.on_scroll(self.handle, 0.0, notches * 3)
            self.frame()

    def move(self, pos: tuple[float, float]) -> None:
        self.input.on_cursor_pos(self.handle, *pos)
        self.frame()

    def click(self, target, button: int, double: bool = False) -> None:
        pos = self.position(target)
        self.move(pos)
        io = imgui.get_io()
        double_click_time = io.mouse_double_click_time
        if double:  # a software renderer's frames may be slower than a person's double-click
            io.mouse_double_click_time = 3600.0
        try:
            for _ in range(2 if double else 1):
                self.input.on_mouse_button(self.handle, button, glfw.PRESS, 0)
                self.frame()
                self.input.on_mouse_button(self.handle, button, glfw.RELEASE, 0)
                self.frame(2)
        finally:
            io.mouse_double_click_time = double_click_time

    def drag(self, start, to, by, button: int, steps: int) -> None:
        x0, y0 = self.position(start)
        if to is not None:
            x1, y1 = self.position(to)
        else:
            x1, y1 = x0 + float(by[0]), y0 + float(by[1])
        self.move((x0, y0))
        self.input.on_mouse_button(self.handle, button, glfw.PRESS, 0)
        self.frame()
        for i in range(1, steps + 1):
            t = i / steps
            self.move((x0 + (x1 - x0) * t, y0 + (y1 - y0) * t))
        self.input.on_mouse_button(self.handle, button, glfw.RELEASE, 0)
        self.frame(2)  # ImGui lets go of the dragged widget a frame after the release

    def resize(self, width: int, height: int) -> None:
        glfw.set_window_size(self.handle, int(width), int(height))
        for _ in range(50):
            self.frame()
            if tuple(self.viewer.window_size) == (int(width), int(height)):
                return
        raise ScriptError(f"the window did not resize to {width}x{height}")
