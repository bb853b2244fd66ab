"""What the raymarch frame costs with hybrid scattering at 1080p (issue 43: at most 2.5 ms), by
settings and by text edits of the tree (bake_variants.edited_tree):
    python lab/experiments/hybrid_raymarch_costs.py OUT.json WORKDIR [scenes]
Settings, each on the tree as it is: k (surface.gradient_factor) 0 and 0.05; the probes' precision
rgba32f and rgba16f; k = 0 with SH order 2 forced (seven textures read with no surface term);
the march's step doubled. Edits:
  count   each pixel's value is the number of non-empty samples its ray took (not an image)
  t1e-3   the march stops at transmittance 1e-3 instead of 1e-6
Prints a JSON line a configuration: ms a frame (GPU timer, after a 16-frame warm-up), the probe
grid and SH order in use, and for `count` the mean samples a pixel."""
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bake_variants import child_rows, edited_tree, keep_rows   # noqa: E402

EDITS = {
    "count": [("glsl/lib/raymarch.glsl", "    float tau_start = -1.0;\n",
               "    float tau_start = -1.0;\n    float steps_taken = 0.0;\n"),
              ("glsl/lib/raymarch.glsl", "        float opacity = 1.0 - exp(-sigma_t * dt);\n",
               "        float opacity = 1.0 - exp(-sigma_t * dt);\n        steps_taken += 1.0;\n"),
              ("glsl/lib/raymarch.glsl", "    return radiance + transmittance * environment;\n#endif\n}",
               "    return vec3(steps_taken);\n#endif\n}")],
    "t1e-3": [("glsl/lib/raymarch.glsl", "transmittance > 1e-6", "transmittance > 1e-3")],
}
CHILD = r'''
import json, sys
from dataclasses import replace
sys.path.insert(0, sys.argv[1])
from app.bench.scenes import bench_scene
from app.gl.context import create_headless_context
from app.rendering.renderer import Renderer
from app.scene import SurfaceSpec
ctx = create_headless_context()
configs = json.loads(sys.argv[3])
for name in sys.argv[2].split(","):
    for c in configs:
        scene = bench_scene(name, 1920, 1080)
        scene = scene.replace(surface=SurfaceSpec(gradient_factor=c["k"], roughness=0.4,
                                                  specular=(0.04,) * 3))
        probes = {}
        if c.get("precision"):
            probes["precision"] = c["precision"]
        if c.get("sh_order") is not None:
            probes["sh_order"] = c["sh_order"]
        if probes:
            scene = scene.replace(probes=replace(scene.probes, **probes))
        r = Renderer(ctx, scene)
        if c.get("step_scale"):
            r.configure(raymarch_step=r.raymarch_step_voxels * c["step_scale"])
        r.render("raymarch", spp=16, seed=1)
        res = r.render("raymarch", spp=16, seed=3)
        row = {"root": sys.argv[1].rsplit("/", 1)[-1], "scene": name, **c,
               "raymarch_ms_per_frame": res.ms_per_sample,
               "probe_grid": list(r.probe_grid.grid) if r.probe_grid is not None else None,
               "sh_order": getattr(r.probe_grid, "sh_order", None),
               "step_voxels": r.raymarch_step_voxels}
        if sys.argv[4] == "count":
            row["mean_samples"] = float(res.image[..., 0].mean())
            row["max_samples"] = float(res.image[..., 0].max())
        print("RESULT " + json.dumps(row), flush=True)
        r.release()
'''
SETTINGS = [{"k": 0.0}, {"k": 0.05}, {"k": 0.0, "sh_order": 2},
            {"k": 0.05, "precision": "rgba16f"}, {"k": 0.0, "precision": "rgba16f"},
            {"k": 0.05, "step_scale": 2.0}]


def main() -> None:
    out, work = Path(sys.argv[1]), Path(sys.argv[2])
    scenes = sys.argv[3] if len(sys.argv) > 3 else "foot,bonsai"
    rows = []
    for name, configs in (("head", SETTINGS), ("count", [{"k": 0.0}, {"k": 0.05}]),
                          ("t1e-3", [{"k": 0.0}, {"k": 0.05}])):
        root = edited_tree(work, name, EDITS.get(name, []))
        got = child_rows(CHILD, name, str(root), scenes, json.dumps(configs), name)
        keep_rows(out, rows, got)


if __name__ == "__main__":
    main()
