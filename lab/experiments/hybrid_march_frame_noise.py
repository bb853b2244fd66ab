"""How much noise a frame does the hybrid raymarcher's drawn surface-or-phase choice (and its
roulette below 1e-3) add? The raymarcher with surfaces draws each sample's choice, unbiased
against the mix by P it replaced (tests/test_hybrid_scattering.py), but a single frame is no
longer the mix's smooth image: each frame's rRMSE against the mix's own 64-frame image
(HYBRID_MARCH_EXPECTATION, the tests' build of the mix), for the drawn march and for the mix (its
jitter alone), at 1, 4 and 16 frames, and k = 0's jitter noise beside them. Bench scenes:
    python lab/experiments/hybrid_march_frame_noise.py OUT.json [scenes] [k] [WxH]"""
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / ".pkg"))
from radiance_probes.bench.scenes import bench_scene                      # noqa: E402
from radiance_probes.gl.context import create_headless_context           # noqa: E402
from radiance_probes.rendering import renderer as renderer_module       # noqa: E402
from radiance_probes.rendering.metrics import rrmse                     # noqa: E402
from radiance_probes.scene_types import SurfaceSpec                      # noqa: E402

FRAMES = (1, 4, 16)


def images(ctx, scene, expectation: bool) -> dict:
    real = renderer_module.Raymarcher

    def marcher(ctx_, stage, defines=None):
        extra = {"HYBRID_MARCH_EXPECTATION": 1} if expectation else {}
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
        mix = images(ctx, hybrid, True)
        drawn = images(ctx, hybrid, False)
        plain = images(ctx, base, False)
        row = {"scene": name, "k": k, "size": [w, h],
               "drawn_vs_mix64": {n: rrmse(drawn[n], mix[64]) for n in FRAMES},
               "mix_vs_mix64": {n: rrmse(mix[n], mix[64]) for n in FRAMES},
               "k0_vs_k0_64": {n: rrmse(plain[n], plain[64]) for n in FRAMES},
               "drawn64_vs_mix64": rrmse(drawn[64], mix[64])}
        rows.append(row)
        print(json.dumps(row), flush=True)
        out.write_text(json.dumps({"rows": rows}, indent=1))


if __name__ == "__main__":
    main()
