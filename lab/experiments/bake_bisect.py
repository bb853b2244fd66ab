"""Where did the bake's speed go? Times the same probe bake with the code of several commits.

Issue 42 item 7: bonsai 128^3 x 64 baked in 131-ish ms on the H100 at f5cefca and in 204 ms on the
H200 now, with every correction off. This script is given folders that each hold one commit's
app/, glsl/ and assets/ (git archive), and for each it starts a fresh interpreter that imports that
commit's package, loads the bench's bonsai scene and bakes the same settings: the sun from the
light grid, no adaptive walks, no sun correction, no sun lobe (each where that commit has the
switch), five timed bakes after a warm-up, plus the commit's own profile (walk time, tracking
steps per walk) where its bench has one.

    python lab/experiments/bake_bisect.py OUT.json ROOT [ROOT ...]

Each ROOT's ../shared/datasets must hold the bonsai raw (link it). Runs on the GPU machine.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

CHILD = r'''
import importlib, json, os, statistics, sys, dataclasses
root = sys.argv[1]
sys.path.insert(0, root)
pkg = "app"
scenes = importlib.import_module(pkg + ".bench.scenes")
ctxm = importlib.import_module(pkg + ".gl.context")
try:
    R = importlib.import_module(pkg + ".rendering.renderer")
except ImportError:
    R = importlib.import_module(pkg + ".render.renderer")
vol = importlib.import_module(pkg + ".volume")
try:
    bake_mod = importlib.import_module(pkg + ".bench.bake")
except Exception:
    bake_mod = None
ctx = ctxm.create_headless_context()
scene = scenes.bench_scene("bonsai", 512, 512)
volume = vol.load_volume(scene.volume, scene.base_dir)
r = R.Renderer(ctx, scene, volume)
plain = dict(walk_sun="grid", walk_adaptive=0.0, walk_sun_correction=0.0, sun_lobe=False)
def apply(r, kw):
    st = getattr(r, "settings", None)
    if st is not None and dataclasses.is_dataclass(st):
        valid = {k: v for k, v in kw.items() if k in {f.name for f in dataclasses.fields(st)}}
        if hasattr(r, "configure"):
            r.configure(**valid)
        else:
            r.settings = dataclasses.replace(st, **valid)
        return sorted(valid)
    done = []
    for k, v in kw.items():
        if hasattr(r, k):
            setattr(r, k, v); done.append(k)
    return done
def rebake(seed, **kw):
    if hasattr(r, "forget_probes"):
        r.forget_probes()
    for a in ("_baked_key", "_bake_key"):
        if hasattr(r, a):
            setattr(r, a, None)
    return r.bake(seed=seed, **kw)
SETTINGS = [tuple(map(int, s.split("x"))) for s in os.environ.get("BISECT_SETTINGS", "64x512,128x64").split(",")]
out = {"root": root, "device": ctxm.describe(ctx) if hasattr(ctxm, "describe") else None}
defaults = getattr(r, "settings", None)
for label, kw in (("plain", plain), ("defaults", {})):
    if label == "defaults" and sys.argv[2] != "1":
        continue
    if label == "defaults" and defaults is not None:
        r.settings = defaults   # the code's own defaults (sun correction and adaptive walks on)
    applied = apply(r, kw)
    for grid, samples in SETTINGS:
        probes = dataclasses.replace(scene.probes, grid=(grid, grid, grid), samples=samples)
        r.set_scene(scene.replace(probes=probes))
        rebake(7)
        times = [rebake(11) for _ in range(5)]
        rec = {"settings": label, "applied": applied, "grid": grid, "samples": samples,
               "bake_ms": statistics.median(times), "runs": times}
        if bake_mod is not None and hasattr(bake_mod, "_profile"):
            try:
                prof = bake_mod._profile(r, 11)
                rec.update({k: prof.get(k) for k in ("bake_walk_ms", "bake_project_ms",
                            "bake_sun_ms", "bake_other_ms", "steps_per_walk", "events_per_walk",
                            "cell_steps_per_walk", "bake_dispatches", "counted_walks")})
            except Exception as e:
                rec["profile_error"] = repr(e)[:200]
        out.setdefault("records", []).append(rec)
        print(json.dumps(rec), file=sys.stderr, flush=True)
print("RESULT " + json.dumps(out))
'''


def main() -> None:
    out = Path(sys.argv[1])
    results = []
    for i, root in enumerate(sys.argv[2:]):
        with_defaults = "1" if i == len(sys.argv[2:]) - 1 or "BISECT_DEFAULTS" in os.environ else "0"
        p = subprocess.run([sys.executable, "-c", CHILD, root, with_defaults],
                           capture_output=True, text=True)
        line = [x for x in p.stdout.splitlines() if x.startswith("RESULT ")]
        rec = json.loads(line[-1][7:]) if line else {"root": root, "error": p.stderr[-2000:]}
        results.append(rec)
        print(root, json.dumps(rec)[:1500], flush=True)
        out.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
