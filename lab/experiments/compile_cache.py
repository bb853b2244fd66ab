"""What a viewer's first load pays for shader compiles, with the driver's shader cache cold and
warm (issue 56: the foot's first load in the replay had a 2.7 s frame, its first guided sample).

Run it twice in fresh processes on the same machine (the second finds the NVIDIA driver's disk
cache, ~/.cache/nvidia/GLCache, filled by the first):

    python3 lab/experiments/compile_cache.py foot; python3 lab/experiments/compile_cache.py foot

It prints one line of JSON: the wall seconds of each first use at 1920x1080 (or `NAME W H`): the
context, a bake, the raymarcher's first frames, guided's first sample (its level 0 and level 1)."""
from __future__ import annotations

import json
import sys
import time

from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context
from radiance_probes.rendering.renderer import Renderer


def main(name: str, width: int = 1920, height: int = 1080) -> None:
    t = {}
    t0 = time.perf_counter()
    ctx = create_headless_context()
    t["context_s"] = time.perf_counter() - t0
    scene = bench_scene(name, width, height)
    r = Renderer(ctx, scene)
    for label, work in (("bake_s", lambda: r.bake(seed=1)),
                        ("raymarch_first_s", lambda: (r.begin("raymarch"), r.add_samples(1))),
                        ("raymarch_second_s", lambda: (r.begin("raymarch"), r.add_samples(1))),
                        ("guided_first_s", lambda: (r.begin("guided"), r.add_samples(1))),
                        ("guided_second_s", lambda: (r.begin("guided"), r.add_samples(1)))):
        ctx.finish()
        t0 = time.perf_counter()
        work()
        ctx.finish()
        t[label] = time.perf_counter() - t0
    print(json.dumps({"scene": name, "renderer": ctx.info["GL_RENDERER"],
                      **{k: round(v, 3) for k, v in t.items()}}))
    r.release()


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "foot", *map(int, sys.argv[2:4]))
