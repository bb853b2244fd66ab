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
from .ceiling import SPEED_CHECK_SLOWER
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


def speed_checks(data: dict, scenes: list[str],
                 when: str = "before the path tracer and before each probe setting") -> list[str]:
    """The device's speed over the run (ceiling.speed_check_ms before each setting): a check
    slower than the scene's fastest by SPEED_CHECK_SLOWER means the GPU was shared or clocked down
    while those records were taken."""
    rows = []
    for s in scenes:
        recs = [r for r in data["records"] if r["scene"] == s and r.get("speed_check_ms")]
        if not recs:
            continue
        checks = sorted({r["speed_check_ms"] for r in recs})
        fastest = checks[0]
        slow = [r for r in recs if r["speed_check_ms"] > SPEED_CHECK_SLOWER * fastest]
        rows.append(f"| {s} | {fastest:.3f} | {checks[len(checks) // 2]:.3f} | {checks[-1]:.3f} | "
                    f"{len(slow)} of {len(recs)} |")
    if not rows:
        return []
    return ["", "## The device's speed during the run", "",
            f"{when[0].upper()}{when[1:]} the run times the same small trilinear march through "
            "the scene's medium (`speed_check_ms`, app/bench/ceiling.py). "
            f"Records taken after a check more than {SPEED_CHECK_SLOWER:.1f}x slower than the "
            "scene's fastest ran on a GPU that was shared or clocked down: their times are not "
            "comparable.", "",
            "| scene | fastest check (ms) | median | slowest | records after a slow check |",
            "|---|---|---|---|---|", *rows]
