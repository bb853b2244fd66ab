"""Issue 33's time-series target: a 50-step series plays at 30 fps or better at 1080p raymarched,
with warm probes; the error after a step change stated against cold bakes.

    python lab/experiments/time_series_bench.py OUT_DIR [--quick] [--steps 50] [--size 192]
        [--width 1920 --height 1080] [--probes 128,64] [--loops 2] [--checks 10,20,30,40,49]

The series: the built-in cloud at SIZE^3 as uint8, moved one voxel along x a step (np.roll; the
cloud is zero at the box's faces, so it slides through without a seam), written to OUT_DIR as
series.npy [t, z, y, x] and shown through a scene with volume.axes "tzyx". Every frame runs the
viewer's loop headless (app/viewer/frame/session.py RenderSession.step with its GPU budgets: a bake
slice, then raymarched samples), as the viewer's Time panel plays it.

1. Playback: after an untimed pass over every step (each step normalised, uploaded and kept,
   shaders compiled), LOOPS passes of one step a frame, each frame waited for (ctx.finish):
   frames a second on the wall clock, the frame times' median and 99th percentile, GPU ms.
2. The error after a step change, warm against cold: at each check step s, the scene is put on
   step s - 1 with its probes fully baked (untimed), then on step s with the bake restarted warm
   (the old probes blended in until the new bake ends: ProbeGrid.restart) or cold (bake_warm off),
   and after n viewer frames the probes as they are then are rendered (REF_FRAMES jittered
   raymarched frames, so the raymarcher's own jitter is not counted) and compared (rRMSE) with
   the same step after a full cold bake. Also while playing (one step a frame) at each check step.

Writes OUT_DIR/results.json and OUT_DIR/report.md. --quick: a 6-step 24^3 series at 64x48 with
8^3 probes (llvmpipe; tests/test_time_series.py runs it).
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from radiance_probes.rendering.metrics import rrmse  # noqa: E402
from radiance_probes.gl.context import create_headless_context, describe, is_software  # noqa: E402
from radiance_probes.rendering.methods.accumulation import Accumulation  # noqa: E402
from radiance_probes.rendering.renderer import Renderer  # noqa: E402
from radiance_probes.io.scene_file import parse_scene  # noqa: E402
from radiance_probes.viewer.frame.session import RenderSession  # noqa: E402
from radiance_probes.io.builtin_volumes import builtin_cloud  # noqa: E402


@dataclass(frozen=True)
class Settings:
    steps: int = 50
    size: int = 192
    width: int = 1920
    height: int = 1080
    probes: tuple[int, int] = (128, 64)       # the viewer's GPU default (device_defaults)
    loops: int = 2
    check_steps: tuple[int, ...] = (10, 20, 30, 40, 49)
    frames_after: tuple[int, ...] = (1, 2, 4, 8, 16, 32, 64)
    ref_frames: int = 16                      # jittered raymarched frames of every image compared
    cache_bytes: int = 8 << 30                # steps kept (host and GPU)


QUICK = Settings(steps=6, size=24, width=64, height=48, probes=(8, 128), loops=2,
                 check_steps=(2, 5), frames_after=(1, 2, 96), ref_frames=4)


def write_series(path: Path, steps: int, size: int) -> Path:
    cloud = builtin_cloud((size, size, size))
    data = np.round(cloud * 255.0).astype(np.uint8)
    series = np.stack([np.roll(data, t, axis=2) for t in range(steps)])
    np.save(path, series)
    return path


def probe_image(r: Renderer, frames: int, seed: int = 7) -> np.ndarray:
    """The raymarched image of the probes as they are now (no bake), `frames` jittered frames."""
    acc = Accumulation(r.ctx, r.scene.camera.width, r.scene.camera.height)
    lent, r._acc = r._acc, acc
    try:
        r.begin("raymarch", seed=seed)
        r.add_samples(frames)
        return acc.read()
    finally:
        r._acc = lent
        acc.release()


def cold_reference(r: Renderer, scene, frames: int, seed: int = 0) -> np.ndarray:
    """Step `scene.time` after a full cold bake with the viewer's seed (a warm bake ends at the
    same probes, so what is left at the end is 0: the partial bake's error alone)."""
    r.configure(bake_warm=False)
    r.set_scene(scene)
    r.invalidate()
    r.bake(seed=seed)
    image = probe_image(r, frames)
    r.configure(bake_warm=True)
    return image


def session_frame(session: RenderSession) -> float:
    """One viewer frame, waited for; its wall ms."""
    start = time.perf_counter()
    session.step(1 << 30, want_probes=True)
    session.ctx.finish()
    return 1e3 * (time.perf_counter() - start)


def run(out: Path, cfg: Settings) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    path = write_series(out / "series.npy", cfg.steps, cfg.size)
    grid, walks = cfg.probes
    scene = parse_scene({"volume": {"path": str(path), "axes": "tzyx"},
                         "camera": {"width": cfg.width, "height": cfg.height},
                         "probes": {"grid": grid, "samples": walks}})
    ctx = create_headless_context()
    r = Renderer(ctx, scene)
    r.resources.step_cache_bytes = cfg.cache_bytes
    session = RenderSession(ctx, scene, renderer=r)
    session.resize(cfg.width, cfg.height)
    session.set_methods(["raymarch"])
    record: dict = {"device": describe(ctx), "settings": cfg.__dict__ | {"probes": list(cfg.probes)},
                    "bake_budget_ms": session.bake_budget_ms,
                    "frame_budget_ms": session.frame_budget_ms}

    # 1. playback, warm
    start = time.perf_counter()
    for t in range(cfg.steps):                    # untimed: every step loaded, uploaded, kept
        session.set_scene(scene.replace(time=t))
        session_frame(session)
    record["first_pass_s"] = time.perf_counter() - start
    walls, gpu = [], []
    start = time.perf_counter()
    for loop in range(cfg.loops):
        for t in range(cfg.steps):
            session.set_scene(scene.replace(time=t))
            walls.append(session_frame(session))
            gpu.append(session.last.total_ms)
    seconds = time.perf_counter() - start
    record["playback"] = {
        "frames": len(walls), "seconds": seconds, "fps": len(walls) / seconds,
        "frame_wall_ms_p50": statistics.median(walls),
        "frame_wall_ms_p99": float(np.percentile(walls, 99)),
        "frame_gpu_ms_p50": statistics.median(gpu), "steps_kept": r.resources.steps_kept}
    print(f"playback: {record['playback']['fps']:.1f} fps over {len(walls)} frames "
          f"(wall p50 {record['playback']['frame_wall_ms_p50']:.1f} ms, p99 "
          f"{record['playback']['frame_wall_ms_p99']:.1f} ms)", flush=True)

    # 2. the error after a step change, warm against cold
    checks = [s for s in cfg.check_steps if 0 < s < cfg.steps]
    refs = {s: cold_reference(r, scene.replace(time=s), cfg.ref_frames, session.seed)
            for s in checks}
    # the bake's own noise, for scale: two full cold bakes of another seed
    record["bake_noise_rrmse"] = float(np.mean([
        rrmse(cold_reference(r, scene.replace(time=s), cfg.ref_frames, 101), refs[s])
        for s in checks]))
    after: dict = {"warm": {}, "cold": {}}
    for variant in ("warm", "cold"):
        for s in checks:
            r.configure(bake_warm=False)
            session.set_scene(scene.replace(time=s - 1))
            r.invalidate()
            r.bake(seed=session.seed)                  # the step before, finished (untimed)
            r.configure(bake_warm=variant == "warm")
            session.set_scene(scene.replace(time=s))
            done = 0
            for n in cfg.frames_after:
                while done < n:
                    session_frame(session)
                    done += 1
                err = rrmse(probe_image(r, cfg.ref_frames), refs[s])
                after[variant].setdefault(str(n), []).append(err)
    record["after_step_change"] = {
        v: {n: {"mean": float(np.mean(e)), "max": float(np.max(e))} for n, e in d.items()}
        for v, d in after.items()}
    # ... and while playing, one step a frame (the image at each check step as it is shown)
    playing: dict = {}
    for variant in ("warm", "cold"):
        r.configure(bake_warm=variant == "warm")
        errs = []
        for t in range(cfg.steps):
            session.set_scene(scene.replace(time=t))
            session_frame(session)
            if t in refs:
                errs.append(rrmse(probe_image(r, cfg.ref_frames), refs[t]))
        playing[variant] = {"mean": float(np.mean(errs)), "max": float(np.max(errs))}
    r.configure(bake_warm=True)
    record["while_playing"] = playing
    record["check_steps"] = checks
    session.set_methods([])
    r.release()
    (out / "results.json").write_text(json.dumps(record, indent=2) + "\n")
    (out / "report.md").write_text(report(record))
    (out / "series.npy").unlink()          # regenerated by the script; not a record
    return record


def report(rec: dict) -> str:
    cfg, play = rec["settings"], rec["playback"]
    lines = [f"# Time series playback ({rec['device']})", "",
             f"{cfg['steps']} steps of a {cfg['size']}^3 uint8 cloud moving one voxel a step, "
             f"{cfg['width']}x{cfg['height']} raymarched, {cfg['probes'][0]}^3 probes x "
             f"{cfg['probes'][1]} walks, the viewer's budgets (bake {rec['bake_budget_ms']} ms, "
             f"frame {rec['frame_budget_ms']} ms), warm restarts.", "",
             f"- playback: **{play['fps']:.1f} fps** over {play['frames']} frames (one step a "
             f"frame; wall p50 {play['frame_wall_ms_p50']:.1f} ms, p99 "
             f"{play['frame_wall_ms_p99']:.1f} ms; GPU p50 {play['frame_gpu_ms_p50']:.1f} ms; "
             f"{play['steps_kept']} steps kept); first pass over the steps "
             f"{rec['first_pass_s']:.1f} s", "",
             "rRMSE against each step's full cold bake of the same seed (mean over the check "
             f"steps {rec['check_steps']}), after n viewer frames on the new step (for scale: "
             f"two full bakes of different seeds differ by {rec['bake_noise_rrmse']:.4f}):", "",
             "| frames after the change | warm | cold |", "|---|---|---|"]
    for n in rec["after_step_change"]["warm"]:
        w, c = rec["after_step_change"]["warm"][n], rec["after_step_change"]["cold"][n]
        lines.append(f"| {n} | {w['mean']:.4f} (max {w['max']:.4f}) | "
                     f"{c['mean']:.4f} (max {c['max']:.4f}) |")
    p = rec["while_playing"]
    lines += ["", f"While playing (one step a frame): warm {p['warm']['mean']:.4f} (max "
              f"{p['warm']['max']:.4f}), cold {p['cold']['mean']:.4f} (max "
              f"{p['cold']['max']:.4f}).", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    a = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    a.add_argument("out")
    a.add_argument("--quick", action="store_true")
    a.add_argument("--steps", type=int)
    a.add_argument("--size", type=int)
    a.add_argument("--width", type=int)
    a.add_argument("--height", type=int)
    a.add_argument("--probes", help="GRID,WALKS")
    a.add_argument("--loops", type=int)
    a.add_argument("--checks", help="the steps whose change is measured, e.g. 10,20,30")
    args = a.parse_args(argv)
    cfg = QUICK if args.quick else Settings()
    changes = {k: getattr(args, k) for k in ("steps", "size", "width", "height", "loops")
               if getattr(args, k) is not None}
    if args.checks:
        changes["check_steps"] = tuple(int(v) for v in args.checks.split(","))
    if args.probes:
        changes["probes"] = tuple(int(v) for v in args.probes.split(","))
    cfg = replace(cfg, **changes)
    if cfg.steps < 2:
        raise SystemExit("error: --steps: a series needs at least 2 steps")
    rec = run(Path(args.out), cfg)
    print(report(rec))
    return 0


if __name__ == "__main__":
    sys.exit(main())
