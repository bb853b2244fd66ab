"""The reference volumetric path tracer pass (glsl/pathtrace.comp)."""
from __future__ import annotations

import struct

import moderngl

from radiance_probes.twins.camera import CameraFrame
from radiance_probes.gl.context import loop_budget, loop_budget_unbounded
from radiance_probes.gl.memory import touch
from radiance_probes.gl.shaders import compute_program, set_uniforms
from radiance_probes.rendering.methods.accumulation import Accumulation
from radiance_probes.rendering.resources import SceneResources
from radiance_probes.rendering.budgets.sample_bands import TILE, tile_grid, tile_rects

LOCAL_SIZE = TILE   # a work group's side: bands start at whole groups (sample_bands.py)
PIXEL_STATE_BYTES = 96  # PathState (80) + next_sample and padding, std430
PIXEL_STATE_BYTES_ENVIRONMENT_MAP = 128  # the same with ENVIRONMENT_MAP (PathState 112)
PATH_STATE_BYTES_AREA_LIGHTS = 32        # and AREA_LIGHTS' light sample (lib/integrator.glsl)


def groups(width: int, height: int,
           shape: tuple[int, int] = (LOCAL_SIZE, LOCAL_SIZE)) -> tuple[int, int]:
    """Work groups of `shape` (pixels across, down) that cover a width x height image."""
    return -(-width // shape[0]), -(-height // shape[1])


def band_edges(height: int, bands: int) -> list[int]:
    """The first rows of `bands` bands of about equal height and the image's height after them,
    every band starting at a multiple of LOCAL_SIZE. A dispatch runs whole groups of LOCAL_SIZE
    rows from its first row and the shader stops only at the image's edge, so a band that ended
    inside a group also ran the next band's first rows: at a fresh start that band's restart then
    began those pixels again and counted their first samples twice (count 4 for 2 samples)."""
    rows = (height + LOCAL_SIZE - 1) // LOCAL_SIZE
    bands = max(1, min(int(bands), rows))
    return [min(height, LOCAL_SIZE * (rows * b // bands)) for b in range(bands + 1)]


class PathTracer:
    def __init__(self, ctx: moderngl.Context, defines: dict | None = None,
                 share: "PathTracer | None" = None):
        """`share`: another pass of the same defines whose program this one uses (with path
        states of its own: a pixel's state belongs to one accumulation)."""
        self.ctx = ctx
        self._owns_program = share is None
        self.program = compute_program(ctx, "pathtrace.comp", defines) if share is None \
            else share.program
        self.state_bytes = (PIXEL_STATE_BYTES_ENVIRONMENT_MAP if (defines or {}).get("ENVIRONMENT_MAP")
                            else PIXEL_STATE_BYTES)
        if (defines or {}).get("AREA_LIGHTS"):
            self.state_bytes += PATH_STATE_BYTES_AREA_LIGHTS
        self.loop_budget, self.loop_reserve = loop_budget(ctx)
        self.states: moderngl.Buffer | None = None
        self.progress = ctx.buffer(reserve=4)
        self.dispatches = 0

    def _states_for(self, acc: Accumulation) -> moderngl.Buffer:
        """The per-pixel path states for acc's size; a new buffer's contents are undefined, which
        only a restart (acc.samples == 0: the shader ignores them) may meet."""
        size = acc.width * acc.height * self.state_bytes
        if self.states is None or self.states.size != size:
            if acc.samples != 0:
                raise RuntimeError("the path states were reallocated in the middle of an "
                                   "accumulation")
            self.allocate(acc.width, acc.height)
        return self.states

    def allocate(self, width: int, height: int) -> None:
        """The path states for images of this size, made now and touched (gl/memory.touch), so
        that the driver gives them memory here and not in the first dispatch
        (Renderer.prepare). Kept where they already have that size."""
        size = width * height * self.state_bytes
        if self.states is not None and self.states.size == size:
            return
        if self.states is not None:
            self.states.release()
        self.states = self.ctx.buffer(reserve=size)
        touch(self.ctx, self.states)

    def dispatch(self, resources: SceneResources, camera: CameraFrame, acc: Accumulation,
                 target_samples: int, seed: int = 0, extra_uniforms: dict | None = None,
                 tiles: tuple[int, int, int, int] | None = None,
                 restart: bool | None = None) -> None:
        """One dispatch towards `target_samples` per pixel of a rectangle of work groups
        (x0, y0, columns, rows of LOCAL_SIZE pixels; None: the whole image); `restart` (default:
        acc was reset, acc.samples == 0) starts every pixel afresh (the shader then ignores the
        stored path states: nothing is cleared or uploaded by the host). acc.samples is the
        caller's to advance."""
        x0, y0, nx, ny = tiles if tiles is not None else (0, 0, *groups(acc.width, acc.height))
        states = self._states_for(acc)
        resources.bind()
        set_uniforms(self.program, resources.uniforms())
        set_uniforms(self.program, extra_uniforms or {})
        set_uniforms(self.program, camera.uniforms())
        set_uniforms(self.program, {"seed": seed & 0xFFFFFFFF, "target_samples": target_samples,
                                    "loop_budget": self.loop_budget, "loop_reserve": self.loop_reserve,
                                    # the shader starts every pixel afresh (no host-side clear)
                                    "restart": int(acc.samples == 0 if restart is None
                                                   else restart),
                                    "tile_offset": (x0 * LOCAL_SIZE, y0 * LOCAL_SIZE)})
        acc.bind_image(0)
        states.bind_to_storage_buffer(1)
        self.progress.bind_to_storage_buffer(2)
        self.program.run(nx, ny)
        self.ctx.memory_barrier(moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT
                                | moderngl.SHADER_STORAGE_BARRIER_BIT)
        self.dispatches += 1

    def run(self, resources: SceneResources, camera: CameraFrame, acc: Accumulation,
            target_samples: int, seed: int = 0, extra_uniforms: dict | None = None,
            bands: int = 1) -> None:
        """Dispatches until every pixel holds `target_samples` samples: per band of rows (the
        image cut into `bands` of about equal height, band_edges), one dispatch where the driver
        has no loop limit; more on llvmpipe, where long paths resume across dispatches. A sample
        left part done by run_groups (acc.groups_done) is finished too: its groups are not begun
        again."""
        tiles_x, _ = tile_grid(acc.width, acc.height)
        edges = {tiles_x * -(-row // LOCAL_SIZE) for row in band_edges(acc.height, bands)}
        edges = sorted(edges | {acc.groups_done})
        for first, end in zip(edges[:-1], edges[1:]):
            # a fresh accumulation's band starts every pixel afresh, but for groups done before
            self.run_groups(resources, camera, acc, (first, end), target_samples, seed,
                            extra_uniforms, fresh=acc.samples == 0 and first >= acc.groups_done)
        acc.samples = target_samples
        acc.groups_done = 0

    def run_groups(self, resources: SceneResources, camera: CameraFrame, acc: Accumulation,
                   groups_range: tuple[int, int], target_samples: int, seed: int = 0,
                   extra_uniforms: dict | None = None, fresh: bool | None = None) -> None:
        """Dispatches work groups [first, end) in raster order (sample_bands.tile_rects: three
        rectangles at most) until each of their pixels holds `target_samples` samples. `fresh`
        (default: acc.samples == 0) begins their pixels afresh in each rectangle's first
        dispatch. acc.samples and acc.groups_done are the caller's to advance."""
        first, end = groups_range
        tiles_x, tiles_y = tile_grid(acc.width, acc.height)
        if not 0 <= first < end <= tiles_x * tiles_y:
            raise ValueError(f"work groups {first}..{end} of {tiles_x * tiles_y}")
        # No driver loop limit: every pixel finishes in one dispatch, and the pending count is
        # neither reset nor read (a write to a buffer the last dispatch used can make the driver
        # wait for that dispatch).
        unbounded = loop_budget_unbounded(self.loop_budget)
        for rect in tile_rects(tiles_x, first, end):
            restart = acc.samples == 0 if fresh is None else fresh  # resumed ones continue
            while True:
                if not unbounded:
                    self.progress.write(bytes(4))
                self.dispatch(resources, camera, acc, target_samples, seed, extra_uniforms,
                              rect, restart)
                restart = False
                if unbounded:
                    break
                (pending,) = struct.unpack("I", self.progress.read())
                if pending == 0:
                    break

    def release(self) -> None:
        if self._owns_program:
            self.program.release()
        self.progress.release()
        if self.states is not None:
            self.states.release()
