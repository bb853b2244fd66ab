"""A volume file opened in the window, read on a thread: the host's work (reading and
normalising the file, the majorant grid's density ranges, the texture's texels, the histogram:
NumPy and IO, about 2 s for the foot on the shared two-core machine) runs while the window keeps
drawing the scene shown, and the GL thread then only uploads (issue 44: no frame of seconds).
The GL context belongs to its thread; nothing here touches it.

    loading = VolumeLoading(scene, scene_path, path, device_limits(ctx), memory_bytes, brick_size)
    each frame: if loading.done: volume = loading.result()   # raises what the thread raised
"""
from __future__ import annotations

import threading
import time

from radiance_probes.gl.textures import texture_payload
from radiance_probes.rendering.grids.majorant_grid import density_ranges
from radiance_probes.rendering.levels.volume_placement import plan_placement
from radiance_probes.io.volume import Volume
from radiance_probes.io.load import load_scene_volume
from radiance_probes.viewer.panels.tf_editor import HISTOGRAM_BINS


def prepare_volume(volume: Volume, limits=None, memory_bytes: int | None = None,
                   brick_size: int | None = None) -> None:
    """What the GL thread would otherwise compute from the volume when it is shown, made now and
    kept in volume.derived: the majorant grid's density ranges, the texture's texels (where
    plan_placement under `limits`, the context's device_limits, puts it in one texture), the
    first channel's histogram."""
    if volume.bricks is None:
        density_ranges(volume)
        if (limits is not None
                and plan_placement(volume, limits, memory_bytes, brick_size).plan is None):
            texture_payload(volume)
    volume.histogram(HISTOGRAM_BINS, 0)


class VolumeLoading:
    def __init__(self, scene, scene_path, path: str, limits=None,
                 memory_bytes: int | None = None, brick_size: int | None = None):
        """`limits`: the context's device_limits (taken on its thread), with the volume memory
        cap and brick size: where the volume will go (prepare_volume)."""
        self.scene, self.scene_path, self.path = scene, scene_path, path
        self._placement = (limits, memory_bytes, brick_size)
        self.started = time.perf_counter()
        self.stage = "reading the file"
        self._volume: Volume | None = None
        self._error: BaseException | None = None
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._work, name="volume-loading", daemon=True)
        self._thread.start()

    def _work(self) -> None:
        try:
            volume = load_scene_volume(self.scene)
            self.stage = "preparing it for the GPU"
            prepare_volume(volume, *self._placement)
            self._volume = volume
        except BaseException as exc:   # reported by result() on the GL thread
            self._error = exc
        finally:
            self._done.set()

    @property
    def done(self) -> bool:
        return self._done.is_set()

    def wait(self, timeout: float | None = None) -> bool:
        return self._done.wait(timeout)

    def result(self) -> Volume:
        """The volume loaded; raises what the thread raised."""
        self._done.wait()
        if self._error is not None:
            raise self._error
        return self._volume

    def progress(self) -> str:
        """A line for the viewer: what is being done, and for how long."""
        return f"opening {self.path}: {self.stage}, {time.perf_counter() - self.started:.1f} s"
