"""What NVIDIA's compiler spends on a first load's shaders, and whether its pragmas cut it without
slowing the passes (issue 56: with the driver's shader cache empty, a load's first frame compiles
for 4.8-7.7 s at 1080p on the H200, guided's path-tracing pass 3.3-4.1 s of it).

    __GL_SHADER_DISK_CACHE=0 python3 lab/experiments/compile_pragmas.py OUT.jsonl [SCENE] [PRAGMAS]

PRAGMAS: `;`-separated lines put after every shader's #version (e.g. "#pragma optionNV(unroll
none)"); empty: the shaders as they are. With the driver's disk cache off every compile is a
cold one. One JSON line: each first use's wall seconds (bake, the raymarcher, guided's level 0 and
level 1), then guided's and the raymarcher's ms a sample at 1920x1080 (median of 5 timed runs of
4 samples, ctx.finish around each), so a pragma's compile saving is read against its cost.
SIZE=WxH: another image size (a try on llvmpipe)."""
from __future__ import annotations

import json
import os
import statistics
import sys
import time

from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl import shaders
from radiance_probes.gl.context import create_headless_context
from radiance_probes.rendering.renderer import Renderer


def main(out: str, name: str = "bonsai", pragmas: str = "") -> None:
    lines = [p.strip() for p in pragmas.split(";") if p.strip()]
    if lines:
        version = shaders.GLSL_VERSION
        shaders.GLSL_VERSION = "\n".join([version, *lines])
    t = {}
    ctx = create_headless_context()
    size = [int(v) for v in os.environ.get("SIZE", "1920x1080").split("x")]
    scene = bench_scene(name, *size)
    r = Renderer(ctx, scene)

    def timed(label, work):
        ctx.finish()
        t0 = time.perf_counter()
        work()
        ctx.finish()
        t[label] = round(time.perf_counter() - t0, 3)
    timed("bake_s", lambda: r.bake(seed=1))
    timed("raymarch_first_s", lambda: (r.begin("raymarch"), r.add_samples(1)))
    timed("guided_level0_s", lambda: r.raymarcher(guided_level0=True))
    timed("guided_first_s", lambda: (r.begin("guided"), r.add_samples(1)))
    per_sample = {}
    for method in ("guided", "raymarch"):
        runs = []
        r.begin(method)
        r.add_samples(2)
        for _ in range(5):
            ctx.finish()
            t0 = time.perf_counter()
            r.add_samples(4)
            ctx.finish()
            runs.append(1e3 * (time.perf_counter() - t0) / 4)
        per_sample[f"{method}_ms_per_sample"] = round(statistics.median(runs), 3)
    record = {"scene": name, "pragmas": lines, "renderer": ctx.info["GL_RENDERER"], **t,
              **per_sample}
    with open(out, "a") as f:
        f.write(json.dumps(record) + "\n")
    print(json.dumps(record))


if __name__ == "__main__":
    main(*sys.argv[1:])
