"""Does a final gather lower the probes' error floor? `probes` reads the probes at its first
scattering event; with Renderer.probe_gather_event = k it traces events 1 .. k-1 as the path tracer
does (sun by shadow ray, phase-sampled direction) and reads the probes at event k, so their error
reaches the image only through light that scattered k times or more. Renders each scene at 512^2
against a path-traced reference (two independent halves) with `probes` at each gather event and a
few probe settings, progressively (16 samples a dispatch), and the raymarcher at 16 frames for
comparison: errors corrected for the reference's noise, GPU times (bake, light grid, frames).
Run on the GPU:
    python lab/experiments/experiment_final_gather.py OUT_DIR [--scenes anisotropic,bonsai,foot]
        [--events 1,2,3] [--spp 16,64,256,1024,4096] [--ref-spp 8192]"""
import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, ".")
from radiance_probes.rendering.metrics import corrected_rrmse, reference_noise, rrmse
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.load import load_volume

SETTINGS = {"anisotropic": "32x256,64x128,128x256", "bonsai": "64x64,128x64",
            "foot": "64x64,128x64", "fuel": "64x64", "hydrogen": "16x16", "thick": "16x16"}

parser = argparse.ArgumentParser()
parser.add_argument("out")
parser.add_argument("--scenes", default="anisotropic,bonsai,foot")
parser.add_argument("--events", default="1,2,3")
parser.add_argument("--spp", default="16,64,256,1024,4096")
parser.add_argument("--ref-spp", type=int, default=8192, help="samples per reference half")
parser.add_argument("--settings", default=None, help="GRIDxWALKS,... (default: per scene)")
args = parser.parse_args()
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)
checkpoints = [int(v) for v in args.spp.split(",")]
events = [int(v) for v in args.events.split(",")]
ctx = create_headless_context()
device = describe(ctx)
print(device, flush=True)
rows = []
for name in args.scenes.split(","):
    base = bench_scene(name, 512, 512)
    if base is None:
        print(f"{name}: dataset absent, skipped", flush=True)
        continue
    r = Renderer(ctx, base, load_volume(base.volume, base.base_dir))
    halves = [r.render("pt", spp=args.ref_spp, seed=s, samples_per_pass=64).image
              for s in (1000003, 2000003)]
    reference = 0.5 * (halves[0] + halves[1])
    noise = reference_noise(*halves)
    print(f"{name}: reference 2 x {args.ref_spp} spp, noise {noise:.5f}", flush=True)

    def row(**kw):
        kw["error"] = corrected_rrmse(kw["rrmse"], noise)
        rows.append(kw)
        print({k: (round(v, 5) if isinstance(v, float) else v) for k, v in kw.items()}, flush=True)

    # the path tracer's own curve at the same checkpoints, same dispatches
    acc_ms = 0.0
    r.begin("pt", seed=7)
    for spp in checkpoints:
        while r.samples < spp:
            acc_ms += r.add_samples(min(16, spp - r.samples))
        row(scene=name, method="pt", spp=spp, rrmse=rrmse(r.image(), reference), render_ms=acc_ms,
            bake_ms=0.0, reference_noise=noise, device=device)
    for setting in (args.settings or SETTINGS.get(name, "32x256")).split(","):
        grid, walks = (int(v) for v in setting.split("x"))
        s = base.replace(probes=replace(base.probes, grid=(grid,) * 3, samples=walks))
        r.set_scene(s)
        bake_ms = r.bake(seed=11)
        light_ms = r.light_grid_ms()
        res = r.render("raymarch", spp=16, seed=11, samples_per_pass=16)
        row(scene=name, method="raymarch", grid=grid, walks=walks, spp=16,
            rrmse=rrmse(res.image, reference), render_ms=res.render_ms, bake_ms=bake_ms,
            light_ms=light_ms, sh_order=r.probe_grid.sh_order)
        for event in events:
            r.configure(gather_event=event)
            acc_ms = 0.0
            r.begin("probes", seed=11)
            for spp in checkpoints:
                while r.samples < spp:
                    acc_ms += r.add_samples(min(16, spp - r.samples))
                row(scene=name, method="probes", gather_event=event, grid=grid, walks=walks,
                    spp=spp, rrmse=rrmse(r.image(), reference), render_ms=acc_ms,
                    bake_ms=bake_ms, light_ms=light_ms, sh_order=r.probe_grid.sh_order,
                    truncated=r.resources.read_stats().get("truncated_paths"))
        r.configure(gather_event=1)
    r.release()
    (out / "final_gather.json").write_text(json.dumps(rows, indent=1))
(out / "final_gather.json").write_text(json.dumps(rows, indent=1))
