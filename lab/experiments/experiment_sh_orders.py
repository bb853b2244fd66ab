"""Is the SH order what holds the anisotropic cloud's error up? Renders the bench's g = 0.8 cloud
at 512^2 against a path-traced reference (two halves of 4096 spp) with probes of each asked-for SH
order at a few probe settings: the raymarcher (16 frames) and `probes` (256 frames), error and GPU
time. Run on the GPU:
    python lab/experiments/experiment_sh_orders.py OUT_DIR [--orders 0,1,2] [--scene anisotropic] [--windows none,hann]
(committed: bench/h100-sh-orders/orders_0_2.json, orders_2_4.json; the first with the settings
128^3 x 256 and 64^3 x 512, the second also 192^3 x 64; windows.json: --windows none,hann,lanczos)."""
import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, ".")
from radiance_probes.rendering.metrics import reference_noise, rrmse
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.load import load_volume

parser = argparse.ArgumentParser()
parser.add_argument("out")
parser.add_argument("--orders", default="2,3,4")
parser.add_argument("--scene", default="anisotropic")
parser.add_argument("--settings", default="128x256,64x512,192x64", help="GRIDxWALKS,...")
parser.add_argument("--windows", default="none", help="SH windows read with each bake (none,hann,lanczos)")
args = parser.parse_args()
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)
ctx = create_headless_context()
print(describe(ctx), flush=True)
base = bench_scene(args.scene, 512, 512)
volume = load_volume(base.volume, base.base_dir)
r = Renderer(ctx, base, volume)
halves = [r.render("pt", spp=4096, seed=s, samples_per_pass=16).image for s in (1000003, 2000003)]
reference = 0.5 * (halves[0] + halves[1])
rows = [{"scene": args.scene, "reference_spp": 8192, "reference_noise": reference_noise(*halves)}]
for setting in args.settings.split(","):
    grid, walks = (int(v) for v in setting.split("x"))
    for order in (int(o) for o in args.orders.split(",")):
        s = base.replace(probes=replace(base.probes, grid=(grid,) * 3, samples=walks, sh_order=order))
        r.set_scene(s)
        bake_ms = r.bake(seed=11)
        for window in args.windows.split(","):
            r.set_scene(s.replace(probes=replace(s.probes, sh_window=window)))   # read-side: no re-bake
            for method, spp in (("raymarch", 16), ("probes", 256)):
                res = r.render(method, spp=spp, seed=11, samples_per_pass=16)
                row = dict(scene=args.scene, grid=grid, walks=walks, order=order, window=window,
                           method=method, frames=spp, rrmse=rrmse(res.image, reference),
                           bake_ms=bake_ms, render_ms=res.render_ms)
                rows.append(row)
                print(row, flush=True)
                if grid == 128 and method == "raymarch" and window == "none":
                    np.save(out / f"{args.scene}_raymarch_order{order}.npy", res.image.astype(np.float16))
np.save(out / f"{args.scene}_reference.npy", reference.astype(np.float32))
(out / "sh_orders.json").write_text(json.dumps(rows, indent=1))
