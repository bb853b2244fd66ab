"""The viewer's window: GLFW with an OpenGL 4.3 core context shared with moderngl, Dear ImGui
through its C++ GLFW and OpenGL3 backends (imgui-bundle), the frame loop, screenshots, and
freeing every GPU resource when the window closes."""
from __future__ import annotations

import ctypes
from pathlib import Path

import moderngl
import numpy as np
from imgui_bundle import imgui, implot

from radiance_probes.gl.context import GL_VERSION, describe
from radiance_probes.viewer import layout
from radiance_probes.viewer.glfw_lib import glfw
from radiance_probes.viewer.input import InputRouter
from radiance_probes.viewer.state import ViewerState
from radiance_probes.viewer.viewer import Viewer

FONT_PIXELS = 15.0
IDLE_WAIT_SECONDS = 0.25


GL_BACK, GL_RGB, GL_UNSIGNED_BYTE, GL_PACK_ALIGNMENT = 0x0405, 0x1907, 0x1401, 0x0D05


def read_back_buffer(width: int, height: int) -> np.ndarray:
    import ctypes.util
    name = ctypes.util.find_library("OpenGL") or ctypes.util.find_library("GL") or "libGL.so.1"
    gl = ctypes.CDLL(name)
    pixels = np.empty((height, width, 3), np.uint8)
    gl.glReadBuffer(GL_BACK)
    gl.glPixelStorei(GL_PACK_ALIGNMENT, 1)
    gl.glReadPixels(0, 0, width, height, GL_RGB, GL_UNSIGNED_BYTE, pixels.ctypes.data_as(ctypes.c_void_p))
    return pixels[::-1].copy()


class WindowError(RuntimeError):
    """No window with an OpenGL 4.3 context could be opened (no display, no GLX, too old GL)."""


def _font_path() -> Path | None:
    import imgui_bundle
    p = Path(imgui_bundle.__file__).parent / "assets" / "fonts" / "Roboto" / "Roboto-Regular.ttf"
    return p if p.is_file() else None


class ViewerWindow:
    def __init__(self, state: ViewerState, width: int = 1280, height: int = 800,
                 title: str = "Radiance probes", vsync: bool = True, file_dialog: str = "auto",
                 volume=None, settings=None):
        """`volume`: the scene's volume, already loaded (else the viewer loads it); `settings`:
        the renderer's RenderSettings (None: the defaults)."""
        self._glfw_errors: list[str] = []
        glfw.ERROR_REPORTING = "ignore"
        glfw.set_error_callback(lambda code, text: self._glfw_errors.append(
            text.decode() if isinstance(text, bytes) else str(text)))
        if not glfw.init():
            raise WindowError(f"GLFW could not start: {'; '.join(self._glfw_errors) or 'no display'}")
        for hint, value in ((glfw.CONTEXT_VERSION_MAJOR, 4), (glfw.CONTEXT_VERSION_MINOR, 3),
                            (glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE),
                            (glfw.OPENGL_FORWARD_COMPAT, True), (glfw.SCALE_TO_MONITOR, True),
                            (glfw.DEPTH_BITS, 24)):
            glfw.window_hint(hint, value)
        self.window = glfw.create_window(width, height, title, None, None)
        if not self.window:
            glfw.terminate()
            raise WindowError("no window with an OpenGL 4.3 core context: "
                              f"{'; '.join(self._glfw_errors) or 'unknown reason'}")
        glfw.make_context_current(self.window)
        glfw.swap_interval(1 if vsync else 0)
        try:
            self.ctx = moderngl.create_context(require=GL_VERSION)
        except Exception as exc:
            glfw.destroy_window(self.window)
            glfw.terminate()
            raise WindowError(f"the window's OpenGL context is not 4.3 core: {exc}") from None
        self._init_imgui()
        try:
            self.viewer = Viewer(self.ctx, state, describe(self.ctx), file_dialog, volume,
                                 settings)
        except BaseException:  # a scene whose volume does not load: close the window, then report
            self._shutdown()
            raise
        self.input = InputRouter(self.window, self.viewer)
        self.input.install()
        self.viewer.input = self.input
        self._update_sizes()
        self.closed = False

    def _init_imgui(self) -> None:
        imgui.create_context()
        implot.create_context()
        io = imgui.get_io()
        io.set_ini_filename(None)  # no imgui.ini in the user's folder
        self.ui_scale = scale = layout.ui_scale(glfw.get_window_content_scale(self.window)[0],
                                         glfw.get_window_size(self.window)[0],
                                         glfw.get_framebuffer_size(self.window)[0])
        imgui.style_colors_dark()
        style = imgui.get_style()
        style.scale_all_sizes(scale)
        style.font_scale_dpi = scale
        font = _font_path()
        if font is not None:
            io.fonts.add_font_from_file_ttf(str(font), FONT_PIXELS)
        address = ctypes.cast(self.window, ctypes.c_void_p).value
        # Our InputRouter installs the callbacks and forwards each event to the backend first.
        imgui.backends.glfw_init_for_opengl(address, False)
        imgui.backends.opengl3_init("#version 430")

    def _update_sizes(self) -> None:
        v = self.viewer
        v.window_size = tuple(max(s, 1) for s in glfw.get_window_size(self.window))
        v.framebuffer_size = tuple(max(s, 1) for s in glfw.get_framebuffer_size(self.window))
        v.ui_scale = self.ui_scale

    # ---- frames --------------------------------------------------------------------------------
    def should_close(self) -> bool:
        return bool(glfw.window_should_close(self.window)) or self.viewer.close_requested

    def frame(self) -> None:
        """One frame: input, renderers, picture, panels, screenshot if asked, swap."""
        v = self.viewer
        self._update_sizes()
        v.apply_input()
        v.render_frame()
        parts = v.session.parts   # the frame's trace (app/viewer/frame/frame_parts.py)
        with parts.part("imgui"):
            imgui.backends.opengl3_new_frame()
            imgui.backends.glfw_new_frame()
            imgui.new_frame()
            v.build_ui()
            imgui.render()
            self.ctx.screen.use()
            imgui.backends.opengl3_render_draw_data(imgui.get_draw_data())
        if v.pending_screenshot:
            from radiance_probes.frontend.render_files import save_or_rescue
            path, v.pending_screenshot = v.pending_screenshot, None
            saved, error = save_or_rescue(lambda p: self.save_screenshot(p), path, "screenshot")
            v.last_screenshot = (path, saved, error)
            if error:
                v.state.error(error)
            else:
                v.state.note(f"saved a screenshot to {saved}")
        with parts.part("swap", gpu=False):
            glfw.swap_buffers(self.window)

    def read_pixels(self) -> np.ndarray:
        """The back buffer as drawn so far, (H, W, 3) uint8, row 0 at the top. (glReadPixels
        directly: moderngl's read of the default framebuffer selects GL_COLOR_ATTACHMENT0,
        which is an invalid read buffer there.)"""
        w, h = self.viewer.framebuffer_size
        self.ctx.screen.use()
        return read_back_buffer(w, h)

    def save_screenshot(self, path: str | Path) -> Path:
        from PIL import Image
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(self.read_pixels(), "RGB").save(p)
        return p.resolve()

    def run(self) -> None:
        """The interactive loop; waits for events while there is nothing left to render."""
        while not self.should_close():
            v = self.viewer
            idle = (v.session.finished(v.state.max_samples, v.state.wants_probes())
                    and v.files.pending is None and not v.stream_wanted())
            if idle:
                glfw.wait_events_timeout(IDLE_WAIT_SECONDS)
            else:
                glfw.poll_events()
            self.frame()

    def poll(self) -> None:
        glfw.poll_events()

    def close(self) -> None:
        """Frees the renderers' GPU resources, ImGui's, the context and the window."""
        if self.closed:
            return
        self.closed = True
        glfw.make_context_current(self.window)
        self.viewer.release()
        self._shutdown()

    def _shutdown(self) -> None:
        imgui.backends.opengl3_shutdown()
        imgui.backends.glfw_shutdown()
        implot.destroy_context()
        imgui.destroy_context()
        self.ctx.release()
        glfw.destroy_window(self.window)
        glfw.terminate()
