"""What every benchmark mode shares: the log line, one progressive run's snapshots with their GPU
times, and the record built from one image (runner, cost and bake modes all import it from here,
so none of them imports another)."""
from __future__ import annotations

import statistics
import sys
import time

import numpy as np

from radiance_probes.gl.dispatch_log import active_log
from radiance_probes.methods import METHODS

from radiance_probes.rendering.methods.pathtracer import PIXEL_STATE_BYTES
from radiance_probes.rendering.budgets.ceiling import SPEED_CHECK_SLOWER
from radiance_probes.bench.clock_log import report_lines as clock_report_lines
from radiance_probes.bench.config import BenchConfig
from radiance_probes.rendering.metrics import corrected_floor, corrected_rrmse, rrmse

ACCUMULATION_BYTES = 16   # RGBA32F running mean per pixel


def log(msg: str) -> None:
    print(f"[bench {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


# The untimed warm-up before each timed run: GPU ms at least (at most WARM_UP_DISPATCHES dispatches).
# nvidia-smi showed the H100 at 390 to 1665 MHz through probe sweeps that leave it mostly idle.
WARM_UP_MS = 50.0
WARM_UP_DISPATCHES = 32
# ... and, on a GPU with a clock to raise, WARM_UP_WALL_S of wall time as well. After a second or
# more with nothing to do (the host compiling a new variant's shaders), the H100 sits at its idle
# 345 MHz and needs about 200 ms under load to reach 1980 MHz (bench/h100-clock-ramp): 50 ms of GPU
# work at the low clock ended the warm-up before that, and the first row timed after a compile
# came out 1.6 to 3x slow. A CPU rasteriser has no clock to raise.
WARM_UP_WALL_S = 0.3


def warm_up(renderer, per_dispatch: int) -> float:
    """Untimed dispatches of the run begun: until WARM_UP_MS of GPU work, and on a GPU (not a CPU
    rasteriser) WARM_UP_WALL_S of wall time as well; else at most WARM_UP_DISPATCHES. GPU ms."""
    from radiance_probes.gl.context import is_software
    clocked = not is_software(renderer.ctx)
    start = time.perf_counter()
    warm_ms, dispatches = 0.0, 0
    while True:
        warm_ms += renderer.add_samples(per_dispatch)
        dispatches += 1
        if clocked:
            elapsed = time.perf_counter() - start
            if (warm_ms >= WARM_UP_MS and elapsed >= WARM_UP_WALL_S) or elapsed >= 10 * WARM_UP_WALL_S:
                return warm_ms
        elif warm_ms >= WARM_UP_MS or dispatches >= WARM_UP_DISPATCHES:
            return warm_ms


def progressive(renderer, method: str, snapshots, seed: int, per_dispatch: int):
    """Yields (samples, image, GPU ms per sample, cumulative GPU ms) at each snapshot of one
    progressive run that adds up to `per_dispatch` samples per pixel in each dispatch (1 sample
    per dispatch leaves most of a big GPU idle behind the longest paths of each wave). The per-sample
    time is the median over full-size dispatches after a warm-up (WARM_UP_MS). The whole run is
    dispatched first, each snapshot copied on the GPU, and the images are read back afterwards:
    reading and measuring an image between the timed dispatches left the GPU idle long enough to
    lower its clock (bench/archive/h100-runs-2's nvidia-smi logs)."""
    # warm-up, not timed: at least WARM_UP_MS of GPU work (and WARM_UP_WALL_S on a GPU), so that
    # a GPU that lowered its clock while the host compiled shaders or measured the previous run's
    # images is back at speed
    renderer.begin(method, seed=seed + 7919)
    warm_up(renderer, per_dispatch)
    acc = renderer.begin(method, seed=seed)
    per_sample: list[float] = []
    cumulative = 0.0
    taken = []
    try:
        for target in sorted(snapshots):
            while renderer.samples < target:
                n = min(per_dispatch, target - renderer.samples)
                ms = renderer.add_samples(n)
                cumulative += ms
                if n == per_dispatch or not per_sample:
                    per_sample.append(ms / n)
            taken.append((target, acc.snapshot(), statistics.median(per_sample), cumulative))
        for target, snapshot, frame_ms, total in taken:
            yield target, snapshot.read(), frame_ms, total
    finally:
        for _, snapshot, *_ in taken:
            snapshot.release()


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
    per_pixel = ACCUMULATION_BYTES + (PIXEL_STATE_BYTES if METHODS[method].path_states else 0)
    rec["image_bytes"] = config.width * config.height * per_pixel
    rec["gpu_bytes"] = rec["image_bytes"] + rec.get("probe_bytes", 0) + rec.get("light_bytes", 0)
    log = active_log()
    if log is not None:   # the longest dispatch since the last record (run_bench keeps a log)
        rec["longest_dispatch_ms"], rec["longest_dispatch"] = log.take()
    return rec


def reference_noise_of(data: dict, scene: str, record: dict | None = None) -> float:
    """The relative noise of the reference a record was measured against (its own field; older
    records: the scene's reference in this file)."""
    if record is not None and record.get("reference_noise") is not None:
        return float(record["reference_noise"])
    return float(data["references"].get(scene, {}).get("noise_rrmse", 0.0))


def run_pixels(data: dict) -> int:
    config = data["meta"].get("config", {})
    return int(config.get("width", 512)) * int(config.get("height", 512))


def floor(data: dict, scene: str) -> float:
    """The smallest error a report states for the scene: the resolution of the error corrected
    for the reference's noise (metrics.corrected_floor, 3 standard errors; about a tenth of the
    reference's own noise at 512^2). Smaller errors are reported only as "below" it."""
    return corrected_floor(reference_noise_of(data, scene), run_pixels(data))


def error_of(data: dict, record: dict) -> float:
    """A record's relative RMSE against the true image: its measured rRMSE corrected for the noise
    of the reference it was measured against (metrics.corrected_rrmse)."""
    return corrected_rrmse(record["rrmse"], reference_noise_of(data, record["scene"], record))


def ms_text(v: float) -> str:
    """Milliseconds to three significant digits (seconds from 1 s)."""
    return f"{v:.3g} ms" if v < 1000 else f"{v / 1000:.3g} s"


def header(title: str, meta: dict) -> list[str]:
    """A mode report's title, device, command and caveat."""
    return [title, "", f"Device: **{meta['device']}**. Command: `{meta.get('command', '')}`.", "",
            *caveat(meta)]


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
            "the scene's medium (`speed_check_ms`, app/rendering/budgets/ceiling.py). "
            f"Records taken after a check more than {SPEED_CHECK_SLOWER:.1f}x slower than the "
            "scene's fastest ran on a GPU that was shared or clocked down: their times are not "
            "comparable.", "",
            "| scene | fastest check (ms) | median | slowest | records after a slow check |",
            "|---|---|---|---|---|", *rows, *clock_report_lines(data.get("meta", {}))]
