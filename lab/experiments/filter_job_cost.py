"""Where a filter job's time goes on the filter's thread, alone and beside the viewer's frames
(issue 56: in the interact-refine replay on the H200 at 1920x1080, once the error curve stopped
pausing the replay for 90 ms a point, an event's filter jobs took 115-215 ms of the thread's wall
time each and 2-3 landed in an event, against 6-9 before).

    python3 lab/experiments/filter_job_cost.py OUT.jsonl [SCENE [W H]]

`alone`: the viewer's shared denoiser (auto device, high quality) on a W x H RGBA image with
albedo and normal guides, REPEATS (8) times after a warm call, signed (a residual with negative
pixels: two filter runs) and not; per call the Denoised's own ms (prepare, filter, check, means)
its wall ms, the thread's CPU ms and the calls' own profile (functions by own time), (time.thread_time: beside the wall ms, what the
thread waited). `beside_frames`: refine's frames (the replay's RenderSession: 128^3 x 64 probes
baked, Denoise on) for 300 frames on a still camera from a restart, each denoiser call on the
filter's thread recorded the same way, with the frames' wall ms meanwhile. One JSON line a phase.
PROFILE_GRID=N: N^3 probes (for a try on llvmpipe). SWITCH_MS=X: the interpreter's switch interval
(sys.setswitchinterval) set to X ms first (Python's default 5 ms): how long a thread that wants
the GIL back waits for one that holds it.
PHASES=alone,beside_frames: the phases to run. PROFILE=0: the calls not profiled (cProfile's own
cost out of their times). Each call and each whole job (FilterWorker._filter: the guide, the
call, the result's copy) also records the thread's user and system ms and minor page faults
(getrusage of the thread), and beside_frames the main thread's over the frames."""
from __future__ import annotations

import cProfile
import json
import os
import pstats
import resource
import statistics
import sys
import time
from dataclasses import replace

import numpy as np

from radiance_probes.bench.config import PRESETS
from radiance_probes.bench.interact import replay_session
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context
from radiance_probes.rendering.denoise import filter as filter_module
from radiance_probes.rendering.denoise import filter_worker
from radiance_probes.rendering.renderer import Renderer

CALLS: list[dict] = []
PROFILE = {"p": cProfile.Profile()}   # the calls' own profile (on whichever thread makes them)
_call = filter_module.Denoiser._call


def _usage() -> tuple[float, float, int]:
    """The calling thread's (user ms, system ms, minor page faults) so far."""
    u = resource.getrusage(resource.RUSAGE_THREAD)
    return 1e3 * u.ru_utime, 1e3 * u.ru_stime, u.ru_minflt


def _recorded(self, *args, **kwargs):
    t, cpu, use = time.perf_counter(), time.thread_time(), _usage()
    if os.environ.get("PROFILE", "1") == "1":
        PROFILE["p"].enable()
    try:
        d = _call(self, *args, **kwargs)
    finally:
        PROFILE["p"].disable()
    after = _usage()
    CALLS.append({"wall": 1e3 * (time.perf_counter() - t),
                  "thread_cpu": 1e3 * (time.thread_time() - cpu), "signed": d.signed,
                  "user_ms": round(after[0] - use[0], 1), "system_ms": round(after[1] - use[1], 1),
                  "page_faults": after[2] - use[2],
                  "device": d.device, **{k: round(v, 2) for k, v in d.ms.items()}})
    return d


filter_module.Denoiser._call = _recorded
JOBS: list[dict] = []      # the filter thread's whole jobs (FilterWorker._filter)
_job = filter_worker.FilterWorker._filter


def _job_recorded(self, job):
    t, use = time.perf_counter(), _usage()
    result = _job(self, job)
    after = _usage()
    JOBS.append({"wall": round(1e3 * (time.perf_counter() - t), 2), "signed": job.signed,
                 "gpu_means": getattr(job, "raw_means", None) is not None,
                 "probe_guide": job.probe_albedo is not None,
                 "user_ms": round(after[0] - use[0], 1), "system_ms": round(after[1] - use[1], 1),
                 "page_faults": after[2] - use[2],
                 **{k: round(v, 2) for k, v in result.ms.items()}})
    return result


filter_worker.FilterWorker._filter = _job_recorded


def _top(n: int = 12) -> list:
    """The calls' functions by own time (ms per call), then the profile starts anew."""
    if os.environ.get("PROFILE", "1") != "1":
        return []
    stats = pstats.Stats(PROFILE["p"])
    calls = max(len(CALLS), 1)
    rows = sorted(stats.stats.items(), key=lambda kv: -kv[1][2])[:n]
    PROFILE["p"] = cProfile.Profile()
    return [[f"{fn[0].split('/')[-1]}:{fn[1]}:{fn[2]}", round(1e3 * st[2] / calls, 2), st[1]]
            for fn, st in rows]


def _summary(calls: list[dict]) -> dict:
    keys = sorted({k for c in calls for k in c if k not in ("signed", "device")})
    return {"calls": len(calls), "device": calls[0]["device"] if calls else None,
            "signed": sum(1 for c in calls if c["signed"]),
            **{f"{k}_median": round(statistics.median(c.get(k, 0.0) for c in calls), 2)
               for k in keys},
            "wall_max": round(max((c["wall"] for c in calls), default=0.0), 2),
            "own_ms_per_call": _top()}


def alone(out, width: int, height: int, repeats: int = 8) -> None:
    rng = np.random.default_rng(1)
    colour = rng.gamma(1.5, 0.3, (height, width, 4)).astype(np.float32)
    residual = (colour - 0.45).astype(np.float32)      # a signed estimate: negatives in it
    albedo = rng.random((height, width, 3), np.float32)
    normal = rng.normal(size=(height, width, 3)).astype(np.float32)
    normal /= np.linalg.norm(normal, axis=2, keepdims=True)
    denoiser = filter_module.shared_denoiser()
    for signed, image in ((False, colour), (True, residual)):
        denoiser(image, albedo, normal, copy=False, signed=signed)   # warm: OIDN's first use
        CALLS.clear()
        PROFILE["p"] = cProfile.Profile()
        for _ in range(repeats):
            denoiser(image.copy(), albedo, normal, copy=False, signed=signed)
        out.write(json.dumps({"phase": "alone", "signed_input": signed, "width": width,
                              "height": height, **_summary(CALLS)}) + "\n")
        out.flush()


def beside_frames(out, name: str, width: int, height: int, frames: int = 300) -> None:
    cfg = PRESETS["interact-refine"]
    ctx = create_headless_context()
    scene = bench_scene(name, width, height)
    grid = int(os.environ.get("PROFILE_GRID", 128))
    scene = scene.replace(probes=replace(scene.probes, grid=(grid, grid, grid), samples=64))
    r = Renderer(ctx, scene)
    session = replay_session(r, cfg)
    session.denoise.set_enabled(True)
    session.resize(width, height)
    r.bake(seed=1)
    session.set_methods(["refine"])
    session.restart()
    CALLS.clear()
    JOBS.clear()
    PROFILE["p"] = cProfile.Profile()
    walls, gpus, started = [], [], time.perf_counter()
    main_before = _usage()
    for _ in range(frames):
        t = time.perf_counter()
        times = session.step(4096, True)
        walls.append(1e3 * (time.perf_counter() - t))
        gpus.append(times.total_ms)
    span = 1e3 * (time.perf_counter() - started)
    main_after = _usage()
    w = np.asarray(walls)
    jobs = {"jobs": len(JOBS), **{f"job_{k}_median": round(statistics.median(j[k] for j in JOBS), 2)
                                  for k in ("wall", "guide_ms", "filter_ms", "copy_ms", "user_ms",
                                            "system_ms", "page_faults") if JOBS},
            "main_thread": {"user_ms": round(main_after[0] - main_before[0], 1),
                            "system_ms": round(main_after[1] - main_before[1], 1),
                            "page_faults": main_after[2] - main_before[2]},
            "per_job": JOBS[:40]}
    out.write(json.dumps({"phase": "beside_frames", "scene": name, "width": width,
                          "height": height, "frames": frames, "span_ms": round(span, 1),
                          "frame_wall_mean": round(float(w.mean()), 2),
                          "frame_gpu_mean": round(float(np.mean(gpus)), 2),
                          "samples": session.views["refine"].acc.samples,
                          **_summary(CALLS), **jobs,
                          "per_call": CALLS[:40]}) + "\n")
    out.flush()
    session.set_methods([])
    r.release()


def main(path: str, name: str = "bonsai", width: int = 1920, height: int = 1080) -> None:
    if os.environ.get("SWITCH_MS"):
        sys.setswitchinterval(float(os.environ["SWITCH_MS"]) / 1e3)
    phases = os.environ.get("PHASES", "alone,beside_frames").split(",")
    with open(path, "w") as out:
        out.write(json.dumps({"switch_interval_ms": 1e3 * sys.getswitchinterval()}) + "\n")
        if "alone" in phases:
            alone(out, width, height)
        if "beside_frames" in phases:
            beside_frames(out, name, width, height)


if __name__ == "__main__":
    main(sys.argv[1], *(sys.argv[2:3] or ["bonsai"]), *map(int, sys.argv[3:5]))
