"""Where a viewer frame's wall time goes beyond its GPU time (issue 56: refine's frames on the
H200 at 1080p take 3-8 ms of wall time more than their GPU time; the edit's first frame 20-35 ms
of host work for 6-10 ms of GPU).

    python3 lab/experiments/frame_host_profile.py [SCENE [W H]]

(PROFILE_SYNC=1: every timed block read as it ends, as before the frame's deferred spans;
PROFILE_GRID=N: N^3 probes, for a try on llvmpipe; PROFILE_METHOD=raymarch: the raymarcher's
frames instead of refine's, as the 4K replay shows them.)

Builds the interact-refine replay's session (RenderSession, Denoise on, 128^3 x 64 probes),
bakes, then runs refine through three phases: a still camera after load, an orbit of 30 frames,
and a transfer-function drag (warm re-bake). Per phase it prints one JSON line: the frames' mean
and p99 wall ms, mean GPU ms (the session's timestamps), the mean ms a frame spent waiting in
blocking timestamp reads (gl/timer._span_ms), the host ms (wall less those waits), and the top
functions by own time (cProfile) of the phase.

PROFILE_LOAD=1: instead, the replay's load (the path tracer's programs used first, as the
reference does; then no probes at all and refine's frames from nothing): one JSON line per frame
over PROFILE_SLOW_MS (default 25) of wall time with its own profile, then the phase's line."""
from __future__ import annotations

import cProfile
import json
import os
import pstats
import sys
import time
from contextlib import contextmanager
from dataclasses import replace

import numpy as np

from radiance_probes.bench.config import PRESETS
from radiance_probes.bench.interact import drag_opacity, orbit, replay_session
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl import timer as gl_timer
from radiance_probes.gl.context import create_headless_context
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.viewer.frame.frame_spans import FrameSpans

WAIT = {"ms": 0.0}
METHOD = os.environ.get("PROFILE_METHOD", "refine")
_span = gl_timer._span_ms


def _timed_span(gl, start, end):
    t = time.perf_counter()
    try:
        return _span(gl, start, end)
    finally:
        WAIT["ms"] += 1e3 * (time.perf_counter() - t)


gl_timer._span_ms = _timed_span

if os.environ.get("PROFILE_SYNC"):   # the frame's timers read as each block ends (before issue 56's
    @contextmanager                  # deferred spans): nothing is tagged, so none defers
    def _untagged(self, tag):
        yield tag
    FrameSpans.tagged = _untagged


def phase(session, label: str, frames: int, scenes=None, top: int = 18) -> None:
    walls, gpus, waits = [], [], []
    prof = cProfile.Profile()
    scenes = list(scenes or [])
    for f in range(frames):
        WAIT["ms"] = 0.0
        t = time.perf_counter()
        prof.enable()
        if f < len(scenes):
            session.set_scene(scenes[f])
        times = session.step(256 if METHOD == "refine" else 1 << 20, True)
        prof.disable()
        walls.append(1e3 * (time.perf_counter() - t))
        gpus.append(times.total_ms)
        waits.append(WAIT["ms"])
    stats = pstats.Stats(prof)
    rows = sorted(stats.stats.items(), key=lambda kv: -kv[1][2])[:top]
    cumulative = sorted(((fn, st) for fn, st in stats.stats.items() if "radiance_probes" in fn[0]
                         or "/app/" in fn[0]), key=lambda kv: -kv[1][3])[:2 * top]
    w, g, q = map(np.asarray, (walls, gpus, waits))
    print(json.dumps({
        "phase": label, "frames": frames,
        "wall_mean": round(float(w.mean()), 2), "wall_p99": round(float(np.percentile(w, 99)), 2),
        "first_wall": round(float(w[0]), 2), "first_gpu": round(float(g[0]), 2),
        "first_wait": round(float(q[0]), 2),
        "gpu_mean": round(float(g.mean()), 2), "wait_mean": round(float(q.mean()), 2),
        "host_mean": round(float((w - q).mean()), 2),
        "own_ms_per_frame": [[f"{fn[0].split('/')[-1]}:{fn[1]}:{fn[2]}",
                              round(1e3 * st[2] / frames, 3), st[1]] for fn, st in rows],
        "cumulative_ms_per_frame": [[f"{fn[0].split('/')[-1]}:{fn[1]}:{fn[2]}",
                                     round(1e3 * st[3] / frames, 3)] for fn, st in cumulative]}),
        flush=True)


def _callers(stats, fn, depth: int = 8) -> list[str]:
    """The chain of largest callers (by time) above `fn`: where the frame's top cost came from."""
    chain = []
    for _ in range(depth):
        callers = stats.stats.get(fn, (0, 0, 0, 0, {}))[4]
        if not callers:
            break
        fn = max(callers, key=lambda c: callers[c][3] if len(callers[c]) > 3 else 0)
        chain.append(f"{fn[0]}:{fn[1]}:{fn[2]}")
    return chain


def load_phase(session, frames: int = 120, top: int = 14) -> None:
    """The load's frames one by one, each profiled on its own; the slow ones printed."""
    slow = float(os.environ.get("PROFILE_SLOW_MS", 25))
    walls = []
    for f in range(frames):
        WAIT["ms"] = 0.0
        prof = cProfile.Profile()
        t = time.perf_counter()
        prof.enable()
        times = session.step(256, True)
        prof.disable()
        wall = 1e3 * (time.perf_counter() - t)
        walls.append(wall)
        if wall <= slow:
            continue
        stats = pstats.Stats(prof)
        own = sorted(stats.stats.items(), key=lambda kv: -kv[1][2])[:top]
        cumulative = sorted(((fn, st) for fn, st in stats.stats.items()
                             if "radiance_probes" in fn[0] or "/app/" in fn[0]),
                            key=lambda kv: -kv[1][3])[:2 * top]
        print(json.dumps({
            "frame": f, "wall": round(wall, 2), "gpu": round(times.total_ms, 2),
            "wait": round(WAIT["ms"], 2), "shown": session.views[METHOD].shown,
            "parts": {k: [None if g is None else round(g, 2), round(w, 2)]
                      for k, (g, w) in times.parts.items()},
            "own": [[f"{fn[0].split('/')[-1]}:{fn[1]}:{fn[2]}", round(1e3 * st[2], 2), st[1]]
                    for fn, st in own],
            "cumulative": [[f"{fn[0].split('/')[-1]}:{fn[1]}:{fn[2]}", round(1e3 * st[3], 2)]
                           for fn, st in cumulative],
            "top_callers": _callers(stats, own[0][0])}), flush=True)
    w = np.asarray(walls)
    print(json.dumps({"phase": "load", "frames": frames, "over_33": int((w > 33).sum()),
                      "wall_p99": round(float(np.percentile(w, 99)), 2),
                      "slowest": [[int(i), round(float(w[i]), 1)] for i in np.argsort(-w)[:8]]}),
          flush=True)


def main(name: str = "chest", width: int = 1920, height: int = 1080) -> None:
    cfg = PRESETS["interact-refine"]
    ctx = create_headless_context()
    scene = bench_scene(name, width, height)
    grid = int(os.environ.get("PROFILE_GRID", 128))   # (a small grid for a try on llvmpipe)
    scene = scene.replace(probes=replace(scene.probes, grid=(grid, grid, grid), samples=64))
    r = Renderer(ctx, scene)
    session = replay_session(r, cfg)
    session.denoise.set_enabled(True)
    session.resize(width, height)
    if os.environ.get("PROFILE_LOAD"):
        r.begin("pt", seed=1)           # the reference's programs, as in the replay
        r.add_samples(1)
        r.invalidate()
        if r.probe_grid is not None:
            r.probe_grid.release()
            r.probe_grid = None
        session.set_methods([METHOD])
        session.restart()
        load_phase(session)
        session.set_methods([])
        r.release()
        return
    r.bake(seed=1)
    session.set_methods([METHOD])
    session.restart()
    phase(session, "still", 60)
    moves = [orbit(scene, 60.0 * (i + 1) / 30) for i in range(30)]
    phase(session, "orbit", 30, moves)
    phase(session, "orbit_after", 30)
    state = moves[-1]
    r.configure(bake_warm=True)
    phase(session, "tf_drag", 60, [drag_opacity(state)])
    session.set_methods([])
    r.release()


if __name__ == "__main__":
    main(*(sys.argv[1:2] or ["chest"]), *map(int, sys.argv[2:4]))
