"""The raymarcher's GPU time per frame against image size (bench/h100-interact found 4 to 16 ms a
sample at 1920x1080 against 1.05 ms at 1280x720, more than the pixel count explains), with the
benchmark's speed check (app/rendering/budgets/ceiling.py) before and after each size, so that a GPU shared or
clocked down at the time shows as such. Sizes are visited twice in different orders.
Usage:
    python lab/experiments/experiment_raymarch_sizes.py OUT.json [--scenes bonsai,foot] [--grids 128x64,64x256] [--sizes WxH,...]"""
import argparse, json, statistics
from dataclasses import replace
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.budgets.ceiling import speed_check_ms
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.io.load import load_volume

parser = argparse.ArgumentParser()
parser.add_argument("out")
parser.add_argument("--scenes", default="bonsai,foot")
parser.add_argument("--grids", default="128x64,64x256")
parser.add_argument("--sizes", default="1920x1080,1280x720,512x512,2560x1440,1280x720,1920x1080")
args = parser.parse_args()
SIZES = [tuple(map(int, s.split("x"))) for s in args.sizes.split(",")]
ctx = create_headless_context()
out = {"meta": {"device": describe(ctx), "args": vars(args), "sizes": SIZES}, "records": []}
for name in args.scenes.split(","):
    scene = bench_scene(name, 512, 512)
    if scene is None:
        continue
    vol = load_volume(scene.volume, scene.base_dir)
    for setting in args.grids.split(","):
        grid, walks = map(int, setting.split("x"))
        r = Renderer(ctx, scene.replace(probes=replace(scene.probes, grid=(grid,) * 3,
                                                         samples=walks)), vol)
        r.bake(seed=1)
        r.bake_light()
        for visit, (w, h) in enumerate(SIZES):
            before = speed_check_ms(r)
            r.begin("raymarch", w, h, seed=visit)
            r.add_samples(1)
            one = [r.add_samples(1) for _ in range(8)]
            many = [r.add_samples(8) / 8 for _ in range(3)]
            after = speed_check_ms(r)
            rec = dict(scene=name, grid=grid, walks=walks, width=w, height=h, visit=visit,
                       frame_ms=statistics.median(one), frame_ms_min=min(one),
                       frame_ms_8=statistics.median(many),
                       ns_per_pixel=1e6 * statistics.median(one) / (w * h),
                       check_before_ms=before, check_after_ms=after)
            print(json.dumps(rec), flush=True)
            out["records"].append(rec)
        r.release()
json.dump(out, open(args.out, "w"), indent=1)
