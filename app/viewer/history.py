"""Undo and redo of scene edits (ctrl+z, ctrl+y): every change of the scene other than the camera
(transfer function, light, crop, probes, bookmarks, ...) is one step once it settles. A drag (a
slider, a curve point, a crop handle) is one step, not one per frame: while a mouse button is
held, changes pile up into the step that the release completes. Camera moves and a time series'
step shown (playing it) are navigation, not edits: they are not steps, and undo keeps the camera
and the time step where they are."""
from __future__ import annotations

from radiance_probes.io.scene_file import CameraSpec, Scene

MAX_STEPS = 200
_ANY_CAMERA = CameraSpec()


def _content(scene: Scene) -> Scene:
    """The scene as an edit sees it: everything but the camera."""
    return scene.replace(camera=_ANY_CAMERA, time=0)


class SceneHistory:
    def __init__(self, scene: Scene):
        self.reset(scene)

    def reset(self, scene: Scene) -> None:
        """Forgets every step (a new scene was opened)."""
        self.committed = scene
        self.undo_steps: list[Scene] = []
        self.redo_steps: list[Scene] = []

    def observe(self, scene: Scene, busy: bool = False) -> None:
        """Called once a frame with the current scene; `busy` while a mouse button is held (a drag
        under way): the step is taken when it is let go."""
        if busy or scene is self.committed:
            return
        if _content(scene) != _content(self.committed):
            self.undo_steps.append(self.committed)
            del self.undo_steps[:-MAX_STEPS]
            self.redo_steps.clear()
        self.committed = scene

    def _move(self, scene: Scene, source: list, target: list) -> Scene | None:
        self.observe(scene)           # an edit not yet taken as a step is one now
        if not source:
            return None
        step = source.pop()
        target.append(self.committed)
        restored = step.replace(camera=scene.camera, time=scene.time)
        self.committed = restored
        return restored

    def undo(self, scene: Scene) -> Scene | None:
        """The scene before the last edit (with the current camera), or None with nothing to undo."""
        return self._move(scene, self.undo_steps, self.redo_steps)

    def redo(self, scene: Scene) -> Scene | None:
        return self._move(scene, self.redo_steps, self.undo_steps)
