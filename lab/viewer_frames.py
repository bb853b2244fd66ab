"""Frame wall times of the viewer in a scripted replay (issue 44: no frame over 250 ms on
llvmpipe). Runs `radiance-probes view SCENE --script STEPS` in this process, the script being
WARMUP frames (shader compiles, the first samples), then a 60-frame replay: an orbit drag of
DRAG_STEPS moves (one frame each, plus the press, the release and ImGui's frame after it) and
still frames up to 60. Every window frame is timed from its start to the end of its swap
(ViewerWindow.frame), which is what a person waits for; the report gives the replay's frames'
max and percentiles, what each did (samples, bands, clock) and the machine's load.

    PYTHONPATH=.pkg .venv/bin/python lab/viewer_frames.py \
        ../shared/datasets/foot_256x256x256_uint8.raw --out out/frames.json [--method pt]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPLAY_FRAMES = 60
DRAG_STEPS = 20


def replay_steps(warmup: int, frames: int = REPLAY_FRAMES, drag_steps: int = DRAG_STEPS) -> list:
    """WARMUP frames, then `frames` frames: a drag across the picture and still frames."""
    drag_frames = drag_steps + 4     # the move to its start, the press, the moves, 2 at release
    return [{"frames": warmup},
            {"drag": {"view": [0.35, 0.5]}, "by": [160, 30], "steps": drag_steps},
            {"frames": frames - drag_frames}]


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene")
    p.add_argument("--out", required=True)
    p.add_argument("--warmup", type=int, default=8)
    p.add_argument("--view-args", nargs=argparse.REMAINDER, default=[],
                   help="more arguments of `view` (e.g. --method raymarch)")
    args = p.parse_args(argv)

    from radiance_probes.cli.main import main as cli
    from radiance_probes.viewer import window as window_module

    records: list[dict] = []
    frame = window_module.ViewerWindow.frame

    def timed_frame(self):
        t0 = time.perf_counter()
        frame(self)
        ms = 1000.0 * (time.perf_counter() - t0)
        s = self.viewer.session
        last = s.last
        records.append({"ms": round(ms, 2), "samples": last.samples, "load1": os.getloadavg()[0],
                        "bake_ms": round(last.bake_ms, 2), "render_ms": round(last.render_ms, 2),
                        "clock": last.clock,
                        "bands": getattr(last, "bands", None), "tiles": getattr(last, "tiles", None),
                        "spp": {m: s.samples(m) for m in s.views},
                        "groups_done": {m: getattr(v.acc, "groups_done", None) for m, v in s.views.items()},
                        "restarts": s.restarts,
                        "light_ms": round(s.renderer.last_light_ms, 1),
                        "compiled": len(s.renderer._raymarchers) + len(s.renderer._passes),
                        "pending": [m for m, v in s.views.items() if getattr(v, "restart_pending", False)],
                        "frame_budget_ms": round(s.pacer.work_budget_ms(s.frame_budget_ms), 1)})
        with open(f"{args.out}l", "a") as log:     # each frame as it comes (a run cut short)
            log.write(json.dumps(records[-1]) + "\n")

    window_module.ViewerWindow.frame = timed_frame
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(f"{args.out}l").write_text("")
    steps = replay_steps(args.warmup)
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump(steps, f)
    load_before = load()
    t0 = time.perf_counter()
    rc = cli.main(["view", args.scene, "--script", f.name, *args.view_args])
    total_s = time.perf_counter() - t0
    load_after = load()
    first = 1 + args.warmup   # ScriptRunner.run draws one frame before the steps
    replay = records[first:first + REPLAY_FRAMES]
    ms = np.array([r["ms"] for r in replay])
    report = {"scene": args.scene, "view_args": args.view_args, "rc": rc,
              "load_before": load_before, "load_after": load_after, "total_s": round(total_s, 1),
              "warmup_ms": [r["ms"] for r in records[:first]],
              "replay": {"frames": len(replay), "max_ms": float(ms.max()),
                         "p50_ms": float(np.percentile(ms, 50)),
                         "p90_ms": float(np.percentile(ms, 90)),
                         "p99_ms": float(np.percentile(ms, 99)),
                         "over_250": int((ms > 250).sum()), "over_100": int((ms > 100).sum())},
              "frames": records}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(report, indent=1))
    r = report["replay"]
    print(f"load {load_before} -> {load_after}; warm-up {report['warmup_ms']}; replay of "
          f"{r['frames']}: max {r['max_ms']:.0f} p50 {r['p50_ms']:.0f} p90 {r['p90_ms']:.0f} "
          f"p99 {r['p99_ms']:.0f} ms, over 250 ms: {r['over_250']}, over 100 ms: {r['over_100']}")
    return rc


if __name__ == "__main__":
    sys.exit(main())
