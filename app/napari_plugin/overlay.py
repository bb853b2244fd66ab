"""The rendered image in napari's canvas: a vispy Image visual that is a child of the canvas's
view box itself (not of its scene), so it is drawn in the view box's pixels, over the layers,
unmoved by napari's camera: each new image is drawn stretched over the whole view box, and it
follows the camera because each one is rendered for the camera as it is (camera_map).

This reaches into napari's vispy canvas (`viewer.window._qt_viewer.canvas.view`), which napari
does not promise: where that is missing, `CanvasOverlay` raises OverlayError, the widget says so
and shows the image in its own panel instead."""
from __future__ import annotations

import numpy as np


class OverlayError(RuntimeError):
    pass


def canvas_of(viewer):
    """napari's VispyCanvas for `viewer`, or OverlayError."""
    try:
        return viewer.window._qt_viewer.canvas
    except AttributeError as exc:
        raise OverlayError(f"napari's canvas is not where this plugin looks for it ({exc})") \
            from None


def canvas_size(viewer) -> tuple[int, int]:
    """(width, height) of napari's view box, in the logical pixels napari's camera zoom counts."""
    w, h = canvas_of(viewer).view.rect.size
    return int(round(w)), int(round(h))


class CanvasOverlay:
    def __init__(self, viewer):
        from vispy.scene.visuals import Image
        from vispy.visuals.transforms import STTransform
        canvas = canvas_of(viewer)
        self._canvas = canvas
        self._view = canvas.view
        self._node = Image(np.zeros((2, 2, 4), np.uint8), parent=self._view,
                           interpolation="linear")
        self._node.order = 10_000          # after the scene
        self._node.set_gl_state("translucent", depth_test=False)
        self._transform = STTransform()
        self._node.transform = self._transform
        self._node.visible = False
        self.shape: tuple[int, int] | None = None

    @property
    def visible(self) -> bool:
        return bool(self._node.visible)

    def show(self, srgb8: np.ndarray) -> None:
        """Draws the (H, W, 3) uint8 picture over the whole view box."""
        h, w = srgb8.shape[:2]
        rgba = np.concatenate([srgb8, np.full((h, w, 1), 255, np.uint8)], axis=2)
        self._node.set_data(rgba)
        vw, vh = self._view.rect.size
        self._transform.scale = (vw / w, vh / h, 1.0)
        self._node.visible = True
        self.shape = (h, w)
        self._node.update()

    def hide(self) -> None:
        self._node.visible = False
        self._node.update()

    def remove(self) -> None:
        self._node.parent = None
