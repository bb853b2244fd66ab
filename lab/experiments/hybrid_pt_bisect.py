"""Where did the hybrid path tracer's speed go? bench/h200-hybrid-cost: a path-traced sample of
the foot at 1080p with surfaces (k = 0.05) cost 1.14x k = 0's at commit 84f6002 and 1.37x at
8d3c17c and since (issue 43's target: at most 1.2x). Times the same samples with the code of
several commits: each ROOT holds one commit's app/, glsl/ and assets/ (git archive); a fresh
interpreter per ROOT imports that commit's package, loads the bench's foot at 1920x1080 and times
32 path-traced samples (and 32 raymarched frames) at k = 0 and k = 0.05 after 16 untimed ones.

    [KS=0,0.05,0,0.05] python lab/experiments/hybrid_pt_bisect.py OUT.json ROOT [ROOT ...]

Each ROOT's ../shared/datasets must hold the foot raw (link it). Runs on the GPU machine."""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bake_variants import (child_rows, keep_rows)  # noqa: E402  (a fresh interpreter, its RESULT lines)

CHILD = r'''
import importlib, json, os, sys
root = sys.argv[1]
sys.path.insert(0, root)
scenes = importlib.import_module("app.bench.scenes")
ctxm = importlib.import_module("app.gl.context")
R = importlib.import_module("app.rendering.renderer")
S = importlib.import_module("app.scene")
ctx = ctxm.create_headless_context()
for k in (float(v) for v in os.environ.get("KS", "0,0.05,0,0.05").split(",")):
    scene = scenes.bench_scene("foot", 1920, 1080)
    scene = scene.replace(surface=S.SurfaceSpec(gradient_factor=k, roughness=0.4,
                                                specular=(0.04,) * 3))
    r = R.Renderer(ctx, scene)
    r.render("pt", spp=16, seed=1)
    res = r.render("pt", spp=32, seed=3)
    r.render("raymarch", spp=16, seed=1)
    ray = r.render("raymarch", spp=32, seed=3)
    print("RESULT " + json.dumps({"root": root, "k": k, "pt_ms_per_sample": res.ms_per_sample,
                                  "raymarch_ms_per_frame": ray.ms_per_sample}), flush=True)
    r.release()
'''


def main() -> None:
    out = Path(sys.argv[1])
    rows = []
    for root in sys.argv[2:]:
        got = child_rows(CHILD, root, root)
        keep_rows(out, rows, got)


if __name__ == "__main__":
    main()
