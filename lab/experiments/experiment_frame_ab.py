"""GPU ms a frame of `probes`, `probes-only` and the raymarcher (512^2, 32^3 x 64 probes; the thick
cloud at SH order 0, the anisotropic cloud at order 2) with the code of the tree given, so that two
checkouts can be timed alternately on one GPU:
    git archive COMMIT app glsl assets | tar -x -C OLD
    for i in 1 2 3; do python lab/experiments/experiment_frame_ab.py OLD; python lab/experiments/experiment_frame_ab.py .; done
(committed: bench/h100-sh-orders/ab_probe_frames.txt, 041d2bb against the SH-order code)."""
import sys, os, json
tree = sys.argv[1]
sys.path.insert(0, tree)
os.chdir(tree)
from dataclasses import replace
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.gl.context import create_headless_context
from radiance_probes.rendering.renderer import Renderer
ctx = create_headless_context()
out = {}
for name in ("thick", "anisotropic"):
    s = bench_scene(name, 512, 512)
    s = s.replace(probes=replace(s.probes, grid=(32,) * 3, samples=64, sh_order=0 if name == "thick" else 2))
    r = Renderer(ctx, s)
    r.bake(seed=1)
    for method in ("probes", "probes-only", "raymarch"):
        r.render(method, spp=256, seed=1, samples_per_pass=16)
        ms = [r.render(method, spp=64, seed=2 + i, samples_per_pass=16).render_ms / 64 for i in range(5)]
        out[f"{name} {method}"] = min(ms)
    r.release()
print(tree, json.dumps({k: round(v, 4) for k, v in out.items()}))
