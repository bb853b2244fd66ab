"""Where the last frame drew each named widget, in window coordinates, so that scripts and tests
can click and drag the real UI through the input callbacks (as a person would)."""
from __future__ import annotations

from imgui_bundle import imgui


class WidgetRects:
    def __init__(self):
        self.rects: dict[str, tuple[float, float, float, float]] = {}
        self._next: dict[str, tuple[float, float, float, float]] = {}
        self.prefix = ""   # put before every name noted (one channel's panel: "channel 1 ")

    def begin_frame(self) -> None:
        self._next = {}

    def end_frame(self) -> None:
        self.rects = self._next

    def note(self, name: str) -> None:
        """Records the rectangle of the widget just submitted."""
        lo, hi = imgui.get_item_rect_min(), imgui.get_item_rect_max()
        self._next[self.prefix + name] = (lo.x, lo.y, hi.x, hi.y)

    def note_point(self, name: str, x: float, y: float, radius: float = 4.0) -> None:
        self._next[self.prefix + name] = (x - radius, y - radius, x + radius, y + radius)

    def centre(self, name: str) -> tuple[float, float]:
        if name not in self.rects:
            known = ", ".join(sorted(self.rects)) or "none"
            raise KeyError(f"no widget named {name!r} in the last frame (known: {known})")
        x0, y0, x1, y1 = self.rects[name]
        return (x0 + x1) / 2, (y0 + y1) / 2
