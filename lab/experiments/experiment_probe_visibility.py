"""Visibility-weighted probe interpolation against leaks (probes.interpolation, lib/probe_visibility.glsl):
the raymarcher's error and frame time with trilinear interpolation and with visibility weights, on
the same baked probes, against a path-traced reference (two halves of 4096 spp, noise-corrected).
Run on the GPU:
    python lab/experiments/experiment_probe_visibility.py OUT.json [--scenes foot,bonsai] [--settings 32x256,64x128]
Variants: "trilinear" and "visibility". The committed records (bench/h100-visibility) also hold
variants measured and dropped: results.json "symmetric" and "visibility4" (commit bfa4b31: any
difference from the point's extinction counted; 4 samples a way), variants.json "k1", "offset" and
"thin" (commit 26da208: 1 sample a way, now the default; one hardware fetch at the weights'
centroid; weights only for optically thin points), both runs' "visibility" with 2 samples a way."""
import argparse
import json
import sys
from dataclasses import replace

sys.path.insert(0, ".")
from radiance_probes.rendering.metrics import corrected_rrmse, reference_noise, rrmse
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.load import load_volume

VARIANTS = ("trilinear", "visibility")
parser = argparse.ArgumentParser()
parser.add_argument("out")
parser.add_argument("--scenes", default="foot,bonsai")
parser.add_argument("--settings", default="32x256,64x128,128x64")
parser.add_argument("--variants", default=",".join(VARIANTS))
parser.add_argument("--frames", type=int, default=16)
parser.add_argument("--size", type=int, default=512)
parser.add_argument("--ref-spp", type=int, default=4096, help="per half")
args = parser.parse_args()
ctx = create_headless_context()
device = describe(ctx)
print(device, flush=True)
rows = []
for name in args.scenes.split(","):
    base = bench_scene(name, args.size, args.size)
    volume = load_volume(base.volume, base.base_dir)
    r = Renderer(ctx, base, volume)
    halves = [r.render("pt", spp=args.ref_spp, seed=s, samples_per_pass=16).image for s in (1000003, 2000003)]
    reference = 0.5 * (halves[0] + halves[1])
    noise = reference_noise(*halves)
    for setting in args.settings.split(","):
        grid, walks = (int(v) for v in setting.split("x"))
        for variant in args.variants.split(","):
            s = base.replace(probes=replace(base.probes, grid=(grid,) * 3, samples=walks,
                                            interpolation=variant))
            r.set_scene(s)
            bake_ms = r.bake(seed=11)
            r.render("raymarch", spp=1, seed=5, samples_per_pass=1)     # compile, warm up
            res = r.render("raymarch", spp=args.frames, seed=11, samples_per_pass=1)
            e = rrmse(res.image, reference)
            row = dict(scene=name, grid=grid, walks=walks, variant=variant, device=device,
                       frames=args.frames, rrmse=e, corrected=corrected_rrmse(e, noise),
                       reference_noise=noise, bake_ms=bake_ms,
                       frame_ms=res.render_ms / args.frames)
            rows.append(row)
            print(json.dumps(row), flush=True)
    r.release()
json.dump(rows, open(args.out, "w"), indent=1)
