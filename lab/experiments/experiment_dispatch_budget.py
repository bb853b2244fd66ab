"""The per-dispatch tail of the path-state passes (pt, probes) and a loop budget per dispatch as
its cure: one dispatch at 1 sample per pixel waits for the pixel with the longest path (28 ms for
`probes` at 1920x1080 on bonsai, against 3 ms a sample at 8 per dispatch; bench/h100-interact).
With a finite loop budget (glsl/pathtrace.comp: iterations one invocation may run), every
invocation stops after about the same work and carries its path over to the next dispatch, starting
new samples within the dispatch as its paths finish. Per budget: each dispatch's GPU ms (median,
max) and the samples per pixel it added (mean, min over pixels, from the accumulation's counts),
so ms per sample against the unbounded dispatch's. With the speed check (app/rendering/budgets/ceiling.py)
before and after.
Usage:
    python lab/experiments/experiment_dispatch_budget.py OUT.json [--scene bonsai] [--size 1920x1080]
        [--budgets 0,4096,1024,512,256,128] [--methods probes,pt] [--compare-renderer]
        (budget 0: unbounded)"""
import argparse, json, statistics
from dataclasses import replace
import numpy as np
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.gl.timer import GpuTimer
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.budgets.ceiling import speed_check_ms
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.io.load import load_volume

parser = argparse.ArgumentParser()
parser.add_argument("out")
parser.add_argument("--scene", default="bonsai")
parser.add_argument("--size", default="1920x1080")
parser.add_argument("--grid", type=int, default=128)
parser.add_argument("--walks", type=int, default=64)
parser.add_argument("--budgets", default="0,4096,1024,512,256,128")
parser.add_argument("--methods", default="probes,pt")
parser.add_argument("--dispatches", type=int, default=12)
parser.add_argument("--compare-renderer", action="store_true",
                    help="also time one and eight samples per dispatch through Renderer.add_samples "
                         "(as the interact replay's dispatch_tail does) and through the dispatch alone")
args = parser.parse_args()
w, h = map(int, args.size.split("x"))
ctx = create_headless_context()
scene = bench_scene(args.scene, w, h)
scene = scene.replace(probes=replace(scene.probes, grid=(args.grid,) * 3, samples=args.walks))
r = Renderer(ctx, scene, load_volume(scene.volume, scene.base_dir))
r.bake(seed=1)
timer = GpuTimer(ctx)
out = {"meta": {"device": describe(ctx), "args": vars(args)}, "records": []}
for method in args.methods.split(","):
    for budget in map(int, args.budgets.split(",")):
        check_before = speed_check_ms(r)
        acc = r.begin(method, w, h, seed=3)
        extra = r.probe_uniforms() if method == "probes" else None
        tracer = r.pass_for(method, r.probe_grid.defines() if method == "probes" else None)
        saved = tracer.loop_budget, tracer.loop_reserve
        if budget > 0:
            tracer.loop_budget, tracer.loop_reserve = budget, 0
        ms, counts = [], []
        previous = np.zeros((h, w), np.float32)
        target = 0
        for i in range(args.dispatches):
            # unbounded: one sample per pixel per dispatch (the viewer's smallest step); bounded: a
            # target far ahead, so the budget alone ends the dispatch
            target = target + 1 if budget == 0 else target + 64
            timer.start()
            tracer.dispatch(r.resources, r.camera, acc, target, r.seed, extra)
            acc.samples = target
            timer.stop()
            ms.append(timer.elapsed_ms)
            count = acc.read_rgba()[..., 3]
            counts.append(count - previous)
            previous = count
        tracer.loop_budget, tracer.loop_reserve = saved
        added = np.stack(counts[1:])          # after the first (warm-up) dispatch
        rec = dict(method=method, budget=budget, width=w, height=h, scene=args.scene,
                   dispatch_ms_p50=statistics.median(ms[1:]), dispatch_ms_max=max(ms[1:]),
                   samples_per_dispatch_mean=float(added.mean()),
                   samples_per_dispatch_min_pixel=float(added.min()),
                   ms_per_sample=float(sum(ms[1:]) / max(added.sum(axis=0).mean(), 1e-9)),
                   pixels_behind_after=int((previous < previous.max()).sum()),
                   check_before_ms=check_before, check_after_ms=speed_check_ms(r))
        print(json.dumps(rec), flush=True)
        out["records"].append(rec)
# The same through the renderer, as the interact replay's dispatch_tail times it (Renderer.add_samples:
# PathTracer.run and the renderer's own timer), and through tracer.dispatch alone.
for method in (args.methods.split(",") if args.compare_renderer else []):
    for way in ("renderer", "dispatch"):
        check_before = speed_check_ms(r)
        acc = r.begin(method, w, h, seed=99)
        extra = r.probe_uniforms() if method == "probes" else None
        tracer = r.pass_for(method, r.probe_grid.defines() if method == "probes" else None)
        def step(n):
            if way == "renderer":
                return r.add_samples(n)
            timer.start()
            tracer.dispatch(r.resources, r.camera, acc, acc.samples + n, r.seed, extra)
            acc.samples += n
            timer.stop()
            return timer.elapsed_ms
        step(1)
        one = [step(1) for _ in range(6)]
        many = [step(8) / 8 for _ in range(3)]
        rec = dict(method=method, way=way, width=w, height=h, scene=args.scene,
                   ms_per_sample_1=statistics.median(one), ms_per_sample_8=statistics.median(many),
                   check_before_ms=check_before, check_after_ms=speed_check_ms(r))
        print(json.dumps(rec), flush=True)
        out["records"].append(rec)
timer.release()
r.release()
json.dump(out, open(args.out, "w"), indent=1)
