"""Opening a volume read brick by brick without stopping the viewer: the host's work (the range
passes, the choice of level, reading and mapping the bricks: seconds for a 2048^3 store) runs on a
thread while the context's thread keeps drawing, and writes the bricks that are ready a few
milliseconds a frame (the GL context belongs to one thread). Meanwhile the viewer shows a preview
(app/io/volume.py zarr_preview: a small level of the store read whole), with a note that says so.

    opening = ProgressiveOpen(ctx, scene, memory_bytes, brick_size)
    each frame: done = opening.poll(budget_s)   # None until the pool is whole, then
                (given, shown, pool) = done      # what Resources.update(placed=...) adopts

The result is the one place_volume gives (plan_placement's level, PoolPlan.rows' bricks): only
when the work is done changes. The reading processes are forked from this thread
(app/io/bricks.py reader_processes); they read the store alone and never touch the context."""
from __future__ import annotations

import queue
import threading
import time

import moderngl

from radiance_probes.gl.brick_pool import FREE_SLOT, empty_pool
from radiance_probes.gl.textures import volume_texture
from radiance_probes.io.scene_file import Scene
from radiance_probes.io.volume import Volume
from radiance_probes.io.load import load_scene_volume
from radiance_probes.rendering.levels.volume_placement import device_limits, plan_placement

# Runs of slots read ahead of the writes, at most (PoolPlan.rows: a run is a row of the slot
# grid at most, some 15 bricks of (B + 2)^3 float32 texels at B = 64: about 17 MiB).
QUEUE_RUNS = 32
# A viewer frame's time for writing the bricks of a volume opening (the viewer, brick_bench).
OPEN_WRITE_BUDGET_S = 0.012
_DONE = object()


class ProgressiveOpen:
    def __init__(self, ctx: moderngl.Context, scene: Scene, memory_bytes: int | None = None,
                 brick_size: int | None = None, camera=None):
        """`camera`: levels mixed by what it sees under the cap (plan_placement)."""
        self.ctx = ctx
        self.scene = scene
        self.started = time.perf_counter()
        self._limits = device_limits(ctx)          # GL queries: on the context's thread
        self._memory_bytes = memory_bytes
        self._brick_size = brick_size
        self._camera = camera
        self._blocks: queue.Queue = queue.Queue(QUEUE_RUNS)
        self._planned = threading.Event()
        self._cancelled = threading.Event()
        self.given: Volume | None = None           # the volume as loaded
        self.placement = None                      # plan_placement's, once the thread has it
        self.pool = None
        self.written = 0
        self.error: BaseException | None = None
        self.stage = "reading the store's value ranges"
        self.done = False
        self._thread = threading.Thread(target=self._work, name="progressive-open", daemon=True)
        self._thread.start()

    # ---- the host's work (a thread) ---------------------------------------------------------
    def _work(self) -> None:
        try:
            self.given = load_scene_volume(self.scene, self._brick_size)
            self.stage = "choosing the level that fits"
            placement = plan_placement(self.given, self._limits, self._memory_bytes,
                                       self._brick_size, self._camera)
            self.placement = placement
            self._planned.set()
            if placement.plan is not None:
                self.stage = "reading bricks"
                rows = placement.plan.rows()
                try:
                    for item in rows:
                        if not self._put(item):
                            return
                finally:
                    rows.close()     # its readers stopped, their shared memory unlinked
        except BaseException as exc:   # reported by poll() on the context's thread
            self.error = exc
        finally:
            self._planned.set()
            self._put(_DONE)

    def _put(self, item) -> bool:
        """Queues item for the context's thread, waiting while the queue is full; False if the
        open was cancelled meanwhile."""
        while not self._cancelled.is_set():
            try:
                self._blocks.put(item, timeout=0.1)
                return True
            except queue.Full:
                pass
        return False

    # ---- the context's thread ---------------------------------------------------------------
    @property
    def bricks_total(self) -> int:
        plan = None if self.placement is None else self.placement.plan
        return 0 if plan is None else plan.resident

    def progress(self) -> str:
        """A line for the viewer: what is being done, and how far."""
        elapsed = time.perf_counter() - self.started
        if self.pool is not None and self.bricks_total:
            return (f"loading {self.scene_name}: {self.written} of {self.bricks_total} bricks "
                    f"({100.0 * self.written / self.bricks_total:.0f}%), {elapsed:.1f} s")
        return f"loading {self.scene_name}: {self.stage}, {elapsed:.1f} s"

    @property
    def scene_name(self) -> str:
        return self.scene.volume.path or "the volume"

    def poll(self, budget_s: float = 0.008):
        """Writes the bricks that are ready for up to `budget_s` seconds; returns (the volume as
        loaded, the volume shown, its texture or BrickPool) once all is written, else None.
        Raises what the thread raised (a VolumeError names the file and the problem)."""
        if self.done:
            raise RuntimeError("ProgressiveOpen.poll after it finished")
        deadline = time.perf_counter() + budget_s
        if not self._planned.is_set():
            return None
        if self.error is not None:
            self._finish_failed()
        placement = self.placement
        if placement.plan is None:             # one texture: uploaded whole, here
            self._thread.join()
            if self.error is not None:
                self._finish_failed()
            self.done = True
            return self.given, placement.shown, volume_texture(self.ctx, placement.shown)
        if self.pool is None:
            self.pool = empty_pool(self.ctx, placement.plan, placement.shown.exact_uint8)
            self.stage = "writing bricks"
        while True:
            try:
                item = self._blocks.get(timeout=max(0.0, deadline - time.perf_counter()))
            except queue.Empty:
                return None
            if item is _DONE:
                self._thread.join()
                if self.error is not None:
                    self._finish_failed()
                written = int((self.pool.brick_of_slot != FREE_SLOT).sum())
                if written != self.bricks_total:
                    self.cancel()
                    raise RuntimeError(f"progressive open wrote {written} of "
                                       f"{self.bricks_total} bricks")
                self.done = True
                pool, self.pool = self.pool, None
                return self.given, placement.shown, pool
            first, bricks, block = item
            self.pool.write_slots(first, bricks, block)
            self.written += len(bricks)
            if time.perf_counter() >= deadline:
                return None

    def _finish_failed(self):
        self.cancel()
        error, self.error = self.error, None
        raise error

    def cancel(self) -> None:
        """Stops the thread's work (it ends after the brick it is reading) and frees the pool."""
        self._cancelled.set()
        self.done = True
        while True:
            try:
                self._blocks.get_nowait()
            except queue.Empty:
                break
        if self.pool is not None:
            self.pool.release()
            self.pool = None

    def wait(self, budget_s: float = 0.05):
        """poll() until done (scripts and tests): the result poll() gives."""
        while True:
            result = self.poll(budget_s)
            if result is not None:
                return result
