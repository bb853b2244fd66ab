"""How much noise a frame does the hybrid raymarcher's roulette (below transmittance 2e-2; 1e-3 when
this was run) add?
Each frame's rRMSE against the 64-frame image of the march that goes on to 1e-6
(HYBRID_MARCH_NO_ROULETTE, the tests' build), for the march as shipped and for that one (its
jitter alone), at 1, 4 and 16 frames, and k = 0's jitter noise beside them. (Run on the march
that drew each sample's surface-or-phase choice, its reference build then the mix by P, it gave
bench/h200-hybrid-cost/hybrid_frame_noise.json.) Bench scenes:
    python lab/experiments/hybrid_march_frame_noise.py OUT.json [scenes] [k] [WxH]"""
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / ".pkg"))
from radiance_probes.bench.scenes import bench_scene                      # noqa: E402
from radiance_probes.gl.context import create_headless_context           # noqa: E402
from radiance_probes.rendering import renderer as renderer_module       # noqa: E402
from radiance_probes.rendering.metrics import rrmse                     # noqa: E402
from radiance_probes.scene.types import SurfaceSpec                      # noqa: E402

FRAMES = (1, 4, 16)


def images(ctx, scene, full: bool) -> dict:
    real = renderer_module.Raymarcher

    def marcher(ctx_, stage, defines=None):
        extra = {"HYBRID_MARCH_NO_ROULETTE": 1} if full else {}
        return real(ctx_, stage, {**(defines or {}), **extra})
    renderer_module.Raymarcher = marcher
    r = renderer_module.Renderer(ctx, scene)
    try:
        out = {n: r.render("raymarch", spp=n, seed=3).image for n in FRAMES}
        out[64] = r.render("raymarch", spp=64, seed=5).image
    finally:
        r.release()
        renderer_module.Raymarcher = real
    return out


def main():
    out = Path(sys.argv[1])
    names = (sys.argv[2] if len(sys.argv) > 2 else "foot,bonsai").split(",")
    k = float(sys.argv[3]) if len(sys.argv) > 3 else 0.05
    w, h = (int(v) for v in (sys.argv[4] if len(sys.argv) > 4 else "1920x1080").split("x"))
    ctx = create_headless_context()
    rows = []
    for name in names:
        base = bench_scene(name, w, h)
        if base is None:
            print(f"{name}: dataset absent, skipped", flush=True)
            continue
        hybrid = base.replace(surface=SurfaceSpec(gradient_factor=k, roughness=0.4,
                                                  specular=(0.04, 0.04, 0.04)))
        full = images(ctx, hybrid, True)
        shipped = images(ctx, hybrid, False)
        plain = images(ctx, base, False)
        row = {"scene": name, "k": k, "size": [w, h],
               "shipped_vs_full64": {n: rrmse(shipped[n], full[64]) for n in FRAMES},
               "full_vs_full64": {n: rrmse(full[n], full[64]) for n in FRAMES},
               "k0_vs_k0_64": {n: rrmse(plain[n], plain[64]) for n in FRAMES},
               "shipped64_vs_full64": rrmse(shipped[64], full[64])}
        rows.append(row)
        print(json.dumps(row), flush=True)
        out.write_text(json.dumps({"rows": rows}, indent=1))


if __name__ == "__main__":
    main()
