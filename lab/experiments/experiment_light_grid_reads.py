"""What the light grid's readers pay: the probe bake's GPU time (walks read the grid at every
event) and the raymarcher's GPU time per frame (it reads the grid at every step), per scene and
light-grid precision (16- and 32-bit texels), median of 3 after a warm-up; with --after-reference,
first a path-traced reference's worth of work (as the benchmark does before a scene's probes).
Written to explain the anisotropic cloud's 2-3x slower walks and frames in bench/h100 against
bench/archive/h100-v3 (the bench runs use 16-bit texels; the A/B that found no difference used 32-bit).
Usage:
    python lab/experiments/experiment_light_grid_reads.py OUT.json [--size N] [--grids 8,64] [--after-reference]
        [--scenes anisotropic,bonsai,thick,foot]"""
import argparse, json, statistics
from dataclasses import replace
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.io.load import load_volume

parser = argparse.ArgumentParser()
parser.add_argument("out")
parser.add_argument("--scenes", default="anisotropic,bonsai,thick,foot")
parser.add_argument("--size", type=int, default=512)
parser.add_argument("--grids", default="8,64")
parser.add_argument("--walks", type=int, default=256)
parser.add_argument("--after-reference", action="store_true")
args = parser.parse_args()
ctx = create_headless_context()
out = {"meta": {"device": describe(ctx), "args": vars(args)}, "records": []}
for name in args.scenes.split(","):
    scene = bench_scene(name, args.size, args.size)
    if scene is None:
        continue
    vol = load_volume(scene.volume, scene.base_dir)
    for grid in map(int, args.grids.split(",")):
        r = Renderer(ctx, scene.replace(probes=replace(scene.probes, grid=(grid,) * 3,
                                                         samples=args.walks)), vol)
        if args.after_reference:
            r.render("pt", spp=256, seed=9, samples_per_pass=64)
        for precision in ("f2", "f4"):
            r.configure(light_precision=precision)
            bakes, frames = [], []
            for i in range(4):
                r._baked_key = None
                r._light_key = None
                r.bake_light()                    # apart: bake() then times the walks alone
                bakes.append(r.bake(seed=i))
                r.begin("raymarch", args.size, args.size, seed=i)
                frames.append(r.add_samples(4) / 4)
            rec = dict(scene=name, grid=grid, walks=args.walks, precision=precision,
                       light_grid=list(r._light.grid), light_axis=r._light.layout.axis,
                       walks_ms=statistics.median(bakes[1:]), frame_ms=statistics.median(frames[1:]))
            print(json.dumps(rec), flush=True)
            out["records"].append(rec)
        r.release()
json.dump(out, open(args.out, "w"), indent=1)
