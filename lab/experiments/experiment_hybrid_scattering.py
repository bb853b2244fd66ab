"""What do surfaces inside the volume (hybrid scattering, the scene's `surface`) cost, and how far
is the raymarcher from the path tracer with them? For each scene and each gradient factor k (0 is
the phase function alone, the code as it was): a path-traced reference (two independent halves),
the raymarcher and `probes` at the same probes, their errors corrected for the reference's noise,
the path tracer's GPU ms per sample and the raymarcher's ms per frame. With k > 0 the raymarcher
runs twice at the same probes: reading the opacity-gradient grid (the product,
app/rendering/grids/opacity_gradient_grid.py) and computing the exact gradient
(LabOptions.opacity_gradient_grid False): the grid's bias against the path tracer and the frame
time it saves. The issue's targets: the hybrid path-traced sample at most 1.2x k = 0's, the
raymarch frame at most 2.5 ms at 1080p, the raymarcher's error with k > 0 at most 1.5x its error
with k = 0.
Run on the GPU (bench scenes, 1080p):
    python lab/experiments/experiment_hybrid_scattering.py OUT_DIR [--scenes foot,bonsai]
        [--k 0,0.05,0.2] [--size 1920x1080] [--ref-spp 1024] [--roughness 0.4] [--specular 0.04]
On llvmpipe: --quick (the built-in head at 32^3, 24 x 24 pixels), or --foot-like N (the foot
bench scene's medium, light and camera with its dataset box-filtered to N^3 voxels, 8^3 probes x
128 walks; the image --size):
    python lab/experiments/experiment_hybrid_scattering.py OUT_DIR --foot-like 64 --size 48x48
        --k 0,0.05,0.2 --ref-spp 4096"""
import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, ".")
from radiance_probes.rendering.metrics import corrected_rrmse, reference_noise, rrmse
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.lab_options import LabOptions
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.levels.volume_placement import coarser
from radiance_probes.io.scene_file import SurfaceSpec, parse_scene
from radiance_probes.io.load import load_scene_volume

parser = argparse.ArgumentParser()
parser.add_argument("out")
parser.add_argument("--scenes", default="foot,bonsai")
parser.add_argument("--k", default="0,0.05,0.2")
parser.add_argument("--size", default="1920x1080")
parser.add_argument("--ref-spp", type=int, default=1024, help="samples per reference half")
parser.add_argument("--probe-spp", type=int, default=64, help="`probes` samples per pixel")
parser.add_argument("--frames", type=int, default=16, help="raymarch frames")
parser.add_argument("--roughness", type=float, default=0.4)
parser.add_argument("--specular", type=float, default=0.04)
parser.add_argument("--quick", action="store_true")
parser.add_argument("--foot-like", type=int, default=0, metavar="N",
                    help="the foot's dataset box-filtered to N^3 voxels (a power-of-two fraction "
                         "of 256), 8^3 probes x 128 walks, the image --size (llvmpipe)")
parser.add_argument("--out-name", default="hybrid_scattering.json")
parser.add_argument("--bake-seeds", default="4",
                    help="comma list: the probes baked with each seed, the raymarcher's errors "
                         "(grid and exact gradient) averaged over them (each bake's in a list)")
parser.add_argument("--probe-variants", default="",
                    help="comma list of precision:sh_order (e.g. rgba16f:auto,rgba16f:1): the "
                         "raymarcher again with probes of each, warm, against the same reference")
args = parser.parse_args()
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)
ctx = create_headless_context()
width, height = (int(v) for v in args.size.split("x"))
if args.quick:
    scenes = {"head": parse_scene({
        "volume": {"builtin": "head", "size": [32, 32, 32]}, "density_scale": 40.0,
        "camera": {"width": 24, "height": 24, "eye": [0.3, 0.4, 1.6]},
        "transfer_function": {"colormap": "grey", "opacity": [[0, 0], [0.3, 0], [1, 1]]},
        "probes": {"grid": 8, "samples": 128}})}
elif args.foot_like:
    foot = bench_scene("foot", width, height)
    if foot is None:
        raise SystemExit("the foot's dataset is absent (../shared/datasets)")
    scenes = {f"foot{args.foot_like}": foot.replace(probes=replace(foot.probes, grid=(8, 8, 8),
                                                                   samples=128))}
else:
    scenes = {name: bench_scene(name, width, height) for name in args.scenes.split(",")}
volumes = {}   # a scene's volume given to the Renderer (the foot box-filtered), else its own
if args.foot_like:
    volume = load_scene_volume(next(iter(scenes.values())))
    while max(volume.dims) > args.foot_like:
        volume = coarser(volume, 64)   # 2 x 2 x 2 voxels averaged, the same box
    volumes[f"foot{args.foot_like}"] = volume
records = []


def mean(values: list) -> float:
    return sum(values) / len(values)


for name, scene in scenes.items():
    if scene is None:
        print(f"{name}: its dataset is absent, skipped", flush=True)
        continue
    for k in (float(v) for v in args.k.split(",")):
        s = scene.replace(surface=SurfaceSpec(gradient_factor=k, roughness=args.roughness,
                                              specular=(args.specular,) * 3))
        r = Renderer(ctx, s, volumes.get(name))
        try:
            a = r.render("pt", spp=args.ref_spp, seed=1, samples_per_pass=16)
            b = r.render("pt", spp=args.ref_spp, seed=2, samples_per_pass=16)
            ref = 0.5 * (a.image + b.image)
            noise = reference_noise(a.image, b.image)
            t = time.time()
            # per bake of the probes: the raymarcher reading the gradient grid, and with k > 0 the
            # same probes and frames with the gradient computed exactly at each sample
            per_bake = {"grid": [], "exact": [], "grid_vs_exact": [], "grid_ms": [],
                        "exact_ms": []}
            for n, bake_seed in enumerate(int(v) for v in args.bake_seeds.split(",")):
                r.forget_probes()
                # the bake (charged here), the compile and the clocks up before the timed frames
                warmed = r.render("raymarch", spp=args.frames, seed=bake_seed)
                if n == 0:
                    warm = warmed
                rm = r.render("raymarch", spp=args.frames, seed=3)
                if n == 0:
                    pr = r.render("probes", spp=args.probe_spp, seed=3)
                per_bake["grid"].append(corrected_rrmse(rrmse(rm.image, ref), noise))
                per_bake["grid_ms"].append(rm.ms_per_sample)
                if k > 0:
                    r.lab = LabOptions(opacity_gradient_grid=False)
                    r.render("raymarch", spp=args.frames, seed=4)   # compile, clocks up
                    ex = r.render("raymarch", spp=args.frames, seed=3)
                    r.lab = LabOptions()
                    per_bake["exact"].append(corrected_rrmse(rrmse(ex.image, ref), noise))
                    per_bake["exact_ms"].append(ex.ms_per_sample)
                    per_bake["grid_vs_exact"].append(rrmse(rm.image, ex.image))
            grid = r.opacity_gradient_grid
            row = {"scene": name, "k": k, "roughness": args.roughness,
                   "specular": args.specular, "width": s.camera.width,
                   "height": s.camera.height,
                   "pt_ms_per_sample": 0.5 * (a.ms_per_sample + b.ms_per_sample),
                   "raymarch_ms_per_frame": mean(per_bake["grid_ms"]), "bake_ms": warm.bake_ms,
                   "probe_precision": r.probe_grid.precision, "sh_order": r.probe_grid.sh_order,
                   "reference_noise": noise,
                   "raymarch_error": mean(per_bake["grid"]),
                   "probes_error": corrected_rrmse(rrmse(pr.image, ref), noise),
                   "gradient_grid": grid is not None and grid.usable,
                   "gradient_grid_bytes": 0 if grid is None else grid.gpu_bytes,
                   "gradient_grid_ms": 0.0 if grid is None else grid.cost_ms,
                   "wall_s": time.time() - t}
            if len(per_bake["grid"]) > 1:
                row["raymarch_error_per_bake"] = per_bake["grid"]
            if k > 0:
                row.update({"raymarch_exact_ms_per_frame": mean(per_bake["exact_ms"]),
                            "raymarch_error_exact_gradient": mean(per_bake["exact"]),
                            "raymarch_grid_vs_exact": mean(per_bake["grid_vs_exact"])})
                if len(per_bake["exact"]) > 1:
                    row["raymarch_error_exact_gradient_per_bake"] = per_bake["exact"]
            variants = []
            for v in filter(None, args.probe_variants.split(",")):
                precision, order = v.split(":")
                probes = replace(s.probes, precision=precision,
                                 sh_order=order if order == "auto" else int(order))
                r.set_scene(s.replace(probes=probes))
                r.invalidate()
                r.render("raymarch", spp=args.frames, seed=4)   # compile, clocks up
                vm = r.render("raymarch", spp=args.frames, seed=3)
                variants.append({"precision": precision, "sh_order": order,
                                 "sh_order_used": r.probe_grid.sh_order,
                                 "raymarch_ms_per_frame": vm.ms_per_sample,
                                 "raymarch_error": corrected_rrmse(rrmse(vm.image, ref), noise)})
            if variants:
                row["probe_variants"] = variants
        finally:
            r.release()
        records.append(row)
        print(json.dumps(row), flush=True)
(out / args.out_name).write_text(json.dumps({"device": describe(ctx),
                                                        "records": records}, indent=1) + "\n")
