"""The bake's GPU time per section (sun, walks, projection) at SH orders 2, 3 and 4 on the bench's
anisotropic cloud, 128^3 x 256 and 64^3 x 512 probes, two profiled bakes each. Run on the GPU:
    python lab/experiments/experiment_sh_order_bake.py OUT.json
(committed: bench/h100-sh-orders/bake_profile_before.json, with the projection of commit 31db697,
and bake_profile_after.json, with today's)."""
import sys, json
from dataclasses import replace
sys.path.insert(0, ".")
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.gl.profiler import GpuProfile
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.load import load_volume
ctx = create_headless_context(); print(describe(ctx))
base = bench_scene("anisotropic", 512, 512)
r = Renderer(ctx, base, load_volume(base.volume, base.base_dir))
rows = []
for grid, walks in ((128, 256), (64, 512)):
    for order in (2, 3, 4):
        s = base.replace(probes=replace(base.probes, grid=(grid,) * 3, samples=walks, sh_order=order))
        r.set_scene(s); r.bake(seed=1)
        for rep in range(2):
            r.invalidate()
            p = GpuProfile()
            ms = r.bake(seed=20 + rep, profile=p)
            row = dict(grid=grid, walks=walks, order=order, bake_ms=ms, sections=p.totals_ms())
            print(row, flush=True); rows.append(row)
json.dump(rows, open(sys.argv[1], "w"), indent=1)
