"""Where the picture goes: the window minus the sidebar (and the slice column at the right,
`right_width`, where the slice view is on), in window coordinates (what the cursor
reports, top-left origin) and in framebuffer pixels (GL's bottom-left origin). On a HiDPI
screen the framebuffer has more pixels than the window has coordinates."""
from __future__ import annotations

SIDEBAR_WIDTH = 370           # the panel's logical pixels, before the UI scale


def view_rect_window(window_size, sidebar_width: float,
                     right_width: float = 0.0) -> tuple[float, float, float, float]:
    w, h = window_size
    x = min(float(sidebar_width), w - 1.0)
    return (x, 0.0, max(w - x - float(right_width), 1.0), float(h))


def view_rect_framebuffer(window_size, framebuffer_size, sidebar_width: float,
                          right_width: float = 0.0) -> tuple[int, int, int, int]:
    scale_x = framebuffer_size[0] / max(window_size[0], 1)
    x, _, w, _ = view_rect_window(window_size, sidebar_width, right_width)
    x0 = int(round(x * scale_x))
    x1 = framebuffer_size[0] if right_width <= 0 else int(round((x + w) * scale_x))
    return (x0, 0, max(x1 - x0, 1), max(framebuffer_size[1], 1))


def render_size(view_rect, render_scale: float) -> tuple[int, int]:
    _, _, w, h = view_rect
    return max(int(round(w * render_scale)), 1), max(int(round(h * render_scale)), 1)


def window_to_framebuffer(point, window_size, framebuffer_size) -> tuple[float, float]:
    """A cursor position as framebuffer pixels, top-left origin."""
    return (point[0] * framebuffer_size[0] / max(window_size[0], 1),
            point[1] * framebuffer_size[1] / max(window_size[1], 1))


def ui_scale(content_scale: float, window_width: int, framebuffer_width: int) -> float:
    """How much larger the panels draw, in window coordinates. Where window coordinates are
    pixels (X11, Windows: GLFW scales the window itself) that is the monitor's content scale;
    where they are points (macOS: the framebuffer is already denser), it is what remains."""
    pixels_per_coordinate = framebuffer_width / max(window_width, 1)
    return max(content_scale / max(pixels_per_coordinate, 1e-6), 1.0)
