"""One front for every render method: the CLI, the viewer and the benchmark all call this."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import moderngl
import numpy as np

from ..camera import camera_frame
from ..gl.timer import GpuTimer
from ..scene import Scene
from ..volume import Volume
from .accumulation import Accumulation
from .pathtracer import PathTracer
from .resources import SceneResources

METHODS = ("pt",)


@dataclass
class RenderResult:
    image: np.ndarray          # linear RGB float32 (H, W, 3)
    method: str
    spp: int
    render_ms: float           # GPU time of the render passes (timestamp queries)
    bake_ms: float = 0.0       # GPU time of probe baking, where the method has one
    stats: dict = field(default_factory=dict)

    @property
    def ms_per_sample(self) -> float:
        return self.render_ms / max(self.spp, 1)


class Renderer:
    def __init__(self, ctx: moderngl.Context, scene: Scene, volume: Volume | None = None):
        self.ctx = ctx
        self.resources = SceneResources(ctx, scene, volume)
        self._pathtracer: PathTracer | None = None
        self._acc: Accumulation | None = None
        self.timer = GpuTimer(ctx)

    @property
    def scene(self) -> Scene:
        return self.resources.scene

    def set_scene(self, scene: Scene, volume: Volume | None = None) -> set[str]:
        return self.resources.update(scene, volume)

    @property
    def pathtracer(self) -> PathTracer:
        if self._pathtracer is None:
            self._pathtracer = PathTracer(self.ctx)
        return self._pathtracer

    def accumulation(self, width: int, height: int) -> Accumulation:
        if self._acc is None or (self._acc.width, self._acc.height) != (width, height):
            if self._acc is not None:
                self._acc.release()
            self._acc = Accumulation(self.ctx, width, height)
        return self._acc

    def render(self, method: str = "pt", spp: int = 64, seed: int = 0,
               width: int | None = None, height: int | None = None, samples_per_pass: int = 1,
               progress: Callable[[int, int], None] | None = None) -> RenderResult:
        """Renders the current scene from scratch with `spp` samples per pixel."""
        if method not in METHODS:
            raise ValueError(f"unknown method '{method}' (known: {', '.join(METHODS)})")
        cam = camera_frame(self.scene.camera, width, height)
        acc = self.accumulation(cam.width, cam.height)
        acc.reset()
        self.resources.reset_stats()
        render_ms = 0.0
        chunk = max(samples_per_pass, 1)
        done = 0
        while done < spp:
            n = min(chunk, spp - done)
            self.timer.start()
            self.pathtracer.run(self.resources, cam, acc, done + n, seed)
            self.timer.stop()
            render_ms += self.timer.elapsed_ms
            done += n
            if progress is not None:
                progress(done, spp)
        rgba = acc.read_rgba()
        stats = self.resources.read_stats()
        stats["min_samples"] = int(rgba[..., 3].min())
        return RenderResult(rgba[..., :3].copy(), method, spp, render_ms, stats=stats)

    def release(self) -> None:
        if self._pathtracer is not None:
            self._pathtracer.release()
        if self._acc is not None:
            self._acc.release()
        self.resources.release()
        self.timer.release()
