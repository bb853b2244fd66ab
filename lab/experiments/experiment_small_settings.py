"""Where the smallest probe settings' time goes (bench/h100-small): the light grid (and its time at
several segment targets), the bake's sections, the walk counters, the raymarched frame per step.
Usage: python lab/experiments/experiment_small_settings.py OUT.json SCENE[,SCENE...]"""
import sys, json, statistics, time
from dataclasses import replace
sys.path.insert(0, ".")
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.bench.records import progressive
from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.gl.profiler import GpuProfile
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.load import load_volume
ctx = create_headless_context(); dev = describe(ctx); print(dev, flush=True)
rows = []
def med(xs): return statistics.median(xs)
for name in sys.argv[2].split(","):
    base = bench_scene(name, 512, 512)
    r = Renderer(ctx, base, load_volume(base.volume, base.base_dir))
    for grid, walks, mb in ((8, 16, None), (16, 16, None), (8, 16, 64), (8, 16, 16), (8, 4, None)):
        s = base.replace(probes=replace(base.probes, grid=(grid,) * 3, samples=walks))
        if mb is not None:
            s = s.replace(max_bounces=mb)
        r.set_scene(s); r.invalidate(); r.bake(seed=1)
        lights, bakes, secs = [], [], []
        for rep in range(5):
            r.invalidate(); lights.append(r.bake_light())
        for rep in range(5):
            r.invalidate(); bakes.append(r.bake(seed=3 + rep))
        for rep in range(3):
            r.invalidate(); r.bake_light(); r._baked_key = None
            p = GpuProfile(); t = r.bake(seed=9 + rep, profile=p); secs.append(p.totals_ms()); p.release()
        g = r.probe_grid
        buf = g.walk_counters(); r._baked_key = None; r.bake(seed=5, counters=buf)
        counts = g.read_walk_counters(buf); buf.release()
        nw = max(counts["walks"], 1)
        row = dict(scene=name, grid=grid, walks=walks, max_bounces=mb or base.max_bounces,
                   fitted=list(g.grid), passes=g.passes_total, light_grid=list(r._light.texture.size),
                   light_ms=med(lights), bake_ms_incl_light=med(bakes),
                   sections={k: med([s_[k] for s_ in secs if k in s_]) for k in secs[0]},
                   dispatches=g.dispatches, events_per_walk=counts["events"] / nw,
                   steps_per_walk=(counts["flight_steps"] + counts["shadow_steps"]) / nw)
        if mb is None and walks == 16 and hasattr(r, "light_segment_target"):
            seg = {}
            for target in (0, 1 << 16, 1 << 17, 1 << 18, 1 << 19):
                r.configure(light_segment_target=target)
                ts = []
                for rep in range(5):
                    r.invalidate(); ts.append(r.bake_light())
                seg[target] = (med(ts), r._light.segments)
            r.configure(light_segment_target=1 << 18)
            row["light_by_segment_target"] = seg
        if mb is None and walks == 16:
            fr = {}
            for step in (0.5, 1.0, 2.0):
                r.configure(raymarch_step=step)
                out = list(progressive(r, "raymarch", [1, 16], 17, 1))
                fr[step] = dict(first_ms=out[0][3], median_ms=out[1][2])
            r.configure(raymarch_step=0.5)
            row["raymarch"] = fr
        print(json.dumps(row), flush=True); rows.append(row)
    r.release()
json.dump(dict(device=dev, rows=rows), open(sys.argv[1], "w"), indent=1)
