"""What every benchmark mode shares: the log line, one progressive run's snapshots with their GPU
times, and the record built from one image (runner, cost and bake modes all import it from here,
so none of them imports another)."""
from __future__ import annotations

import statistics
import sys
import time

import numpy as np

from ..render.pathtracer import PIXEL_STATE_BYTES
from .config import BenchConfig
from .metrics import rrmse

ACCUMULATION_BYTES = 16   # RGBA32F running mean per pixel


def log(msg: str) -> None:
    print(f"[bench {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def progressive(renderer, method: str, snapshots, seed: int, per_dispatch: int):
    """Yields (samples, image, GPU ms per sample, cumulative GPU ms) at each snapshot of one
    progressive run that adds up to `per_dispatch` samples per pixel in each dispatch (1 sample
    per dispatch leaves most of a big GPU idle behind the longest paths of each wave). The per-sample
    time is the median over full-size dispatches after a warm-up dispatch."""
    renderer.begin(method, seed=seed + 7919)   # warm-up, not timed
    renderer.add_samples(per_dispatch)
    renderer.begin(method, seed=seed)
    per_sample: list[float] = []
    cumulative = 0.0
    for target in sorted(snapshots):
        while renderer.samples < target:
            n = min(per_dispatch, target - renderer.samples)
            ms = renderer.add_samples(n)
            cumulative += ms
            if n == per_dispatch or not per_sample:
                per_sample.append(ms / n)
        yield target, renderer.image(), statistics.median(per_sample), cumulative


def make_record(base: dict, config: BenchConfig, method: str, frames: int, image: np.ndarray,
                reference: np.ndarray, timing: tuple[float, float], bake_ms: float = 0.0,
                **extra) -> dict:
    """One result: `timing` is (median GPU ms per sample, summed GPU ms of the render so far);
    `extra` adds the setting's own fields (probe_bytes and light_bytes count in gpu_bytes)."""
    frame_ms, render_ms = timing
    rec = dict(base, method=method, spp=frames, frame_ms=frame_ms, bake_ms=bake_ms,
               render_ms=render_ms, total_ms=bake_ms + render_ms, rrmse=rrmse(image, reference),
               samples_per_dispatch=config.samples_per_dispatch,
               probe_grid=None, probe_samples=None, gpu_bytes=0)
    rec.update(extra)
    # Per-pixel buffers: the accumulation image and, for the path-state passes, PathState.
    per_pixel = ACCUMULATION_BYTES + (0 if method == "raymarch" else PIXEL_STATE_BYTES)
    rec["image_bytes"] = config.width * config.height * per_pixel
    rec["gpu_bytes"] = rec["image_bytes"] + rec.get("probe_bytes", 0) + rec.get("light_bytes", 0)
    return rec


def caveat(meta: dict) -> list[str]:
    """A run's known shortcoming, stated at the top of its report (results.json's meta.caveat)."""
    return [f"**Caveat:** {meta['caveat']}", ""] if meta.get("caveat") else []
