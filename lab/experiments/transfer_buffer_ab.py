"""A/B: transfer table read with texelFetch (A) or from an SSBO (B, TRANSFER_BUFFER)."""
import sys, json, statistics
from dataclasses import replace
sys.path.insert(0, ".")
import numpy as np
import app.gl.shaders as shaders
from app.bench.scenes import bench_scene
from app.gl.context import create_headless_context, describe
from app.render.renderer import Renderer
from app.volume import load_volume
import app.render.renderer as renderer_mod, app.render.probes as probes_mod
orig = shaders.compute_program
MODE = {"b": False}
def patched(ctx, name, defines=None, text=None):
    d = dict(defines or {})
    if MODE["b"]:
        d["TRANSFER_BUFFER"] = 1
    return orig(ctx, name, d, text)
shaders.compute_program = patched
import app.render.pathtracer, app.render.raymarch, app.render.light_transmittance, app.render.majorant_grid, app.render.visible_region
for m in (renderer_mod, probes_mod, app.render.pathtracer, app.render.raymarch, app.render.light_transmittance, app.render.majorant_grid, app.render.visible_region):
    if hasattr(m, "compute_program"):
        m.compute_program = patched
ctx = create_headless_context(); print(describe(ctx), flush=True)
scenes = sys.argv[1].split(",")
out = {}
imgs = {}
for rep in range(2):
  for mode in ("a", "b"):
    MODE["b"] = mode == "b"
    for name in scenes:
        base = bench_scene(name, 512, 512)
        vol = load_volume(base.volume, base.base_dir)
        for grid, walks in ((8, 16), (64, 64)):
            s = base.replace(probes=replace(base.probes, grid=(grid,) * 3, samples=walks))
            r = Renderer(ctx, s, vol)
            r.bake(seed=1)
            bakes = []
            for i in range(5):
                r.invalidate(); bakes.append(r.bake(seed=1))
            r.render("raymarch", spp=16, seed=1, samples_per_pass=16)
            rm = [r.render("raymarch", spp=16, seed=1, samples_per_pass=16).render_ms / 16 for i in range(5)]
            res = r.render("raymarch", spp=16, seed=1, samples_per_pass=16)
            key = f"{name} {grid}x{walks}"
            if grid == 8:
                r.render("pt", spp=16, seed=1, samples_per_pass=16)
                pt = [r.render("pt", spp=64, seed=1, samples_per_pass=16).render_ms / 64 for i in range(3)]
                ptimg = r.render("pt", spp=16, seed=5, samples_per_pass=16).image
                out.setdefault(f"{name} pt ms/spp", {}).setdefault(mode, []).append(min(pt))
                if rep == 0: imgs[(name, "pt", mode)] = ptimg
            out.setdefault(key + " bake", {}).setdefault(mode, []).append(statistics.median(bakes))
            out.setdefault(key + " raymarch ms/fr", {}).setdefault(mode, []).append(min(rm))
            if rep == 0: imgs[(key, mode)] = res.image
            r.release()
            print(mode, key, round(statistics.median(bakes), 4), round(min(rm), 4), flush=True)
for k, v in out.items():
    print(k, {m: [round(x, 4) for x in xs] for m, xs in v.items()})
same = {str(k[:-1]): bool(np.array_equal(imgs[k], imgs[k[:-1] + ("b",)])) for k in imgs if k[-1] == "a"}
print("identical images:", same)
