"""What importance sampling an environment map gains: renders a scene with a map (default
assets/scenes/sky.json, whose small sun is in the map) with the map's samples and MIS, and with
phase sampling alone (ENVIRONMENT_MAP_SAMPLING 0), two seeds each, and prints per method the GPU
time per sample, the relative noise of the mean (from the two seeds), the noise of one sample,
the efficiency (1 / (variance x time)) and the brightest pixel against the converged mean.

    python lab/experiments/envmap_sampling.py [SCENE.json] [SIZE] [SPP]      # default 64 px, 64 spp
"""
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from radiance_probes.gl.context import create_headless_context, describe  # noqa: E402
from radiance_probes.rendering.lab_options import LabOptions  # noqa: E402
from radiance_probes.rendering.renderer import Renderer  # noqa: E402
from radiance_probes.io.scene_file import load_scene  # noqa: E402

root = Path(__file__).resolve().parents[2]
scene = load_scene(sys.argv[1] if len(sys.argv) > 1 else root / "assets/scenes/sky.json")
size = int(sys.argv[2]) if len(sys.argv) > 2 else 64
spp = int(sys.argv[3]) if len(sys.argv) > 3 else 64
ctx = create_headless_context()
print(f"device: {describe(ctx)}; {size} x {size}, {spp} spp per seed")
r = Renderer(ctx, scene)
results = {}
for name, sampling in (("map sampling + MIS", True), ("phase sampling only", False)):
    r.lab = LabOptions(environment_sampling=sampling)
    images, ms = [], 0.0
    for seed in (1, 2):
        res = r.render("pt", spp=spp, seed=seed, width=size, height=size, samples_per_pass=spp)
        images.append(res.image)
        ms += res.render_ms
    results[name] = (images, ms / (2 * spp))
ref = sum(sum(imgs) for imgs, _ in results.values()) / 4
rms = math.sqrt(np.mean(ref ** 2))
for name, (images, ms) in results.items():
    a, b = images
    noise = math.sqrt(np.mean((a - b) ** 2)) / 2 / rms          # of the 2 x spp mean
    per_sample = noise * math.sqrt(2 * spp)
    print(f"{name:22s} {ms:8.2f} ms/sample  relative noise {noise:.4f} at {2 * spp} spp "
          f"(one sample {per_sample:.2f})  efficiency {1 / (per_sample ** 2 * ms):.4g}  "
          f"brightest pixel / mean {max(a.max(), b.max()) / ref.mean():.1f}")
r.release()
