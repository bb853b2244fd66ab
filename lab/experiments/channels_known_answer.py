"""Issue 33's channel target on a GPU: a 3-channel volume renders each channel's colour where it
is alone and their mix where they overlap, against the combined medium's closed form; and what
several channels cost.

    python lab/experiments/channels_known_answer.py OUT_DIR [--quick] [--size 512] [--spp 4096]

1. Known answer: a slab 1 x 1 x 1/8 in four quadrants, channel 0 alone, 1 alone, 2 alone and all
   three, constant in each (tests/test_channels.py's scene at a larger size), lit by the sun
   straight down its normal, one scattering event (max_bounces 1), no environment. Per quadrant
   the closed form of single scattering off a homogeneous slab, averaged over the pixels well
   inside the quadrant, against the path tracer (with its standard error from two seeds), the
   raymarcher (compute and fragment) and `probes`: relative error per colour.
2. Cost: the built-in cloud split into 1 to 4 channels (each a quarter of the box along x, the
   same medium in sum), the path tracer's ms a sample and the raymarcher's ms a frame at SIZE^2
   for each count (1: the one-channel code, MEDIUM_CHANNELS undefined).

Writes OUT_DIR/results.json and OUT_DIR/report.md.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from radiance_probes.gl.context import create_headless_context, describe  # noqa: E402
from radiance_probes.rendering.renderer import Renderer  # noqa: E402
from radiance_probes.io.scene_file import parse_scene  # noqa: E402
from radiance_probes.twins.camera import camera_frame  # noqa: E402
from radiance_probes.io.builtin_volumes import builtin_cloud  # noqa: E402

OPACITY = (0.3, 0.6, 1.0)
COLOURS = ((1.0, 0.25, 0.25), (0.25, 1.0, 0.25), (0.3, 0.3, 1.0))
SCALE = 6.0
IRRADIANCE = 2.0
ALBEDO = 0.9
HALF_THICKNESS = 0.5 * 4 / 32


def slab() -> np.ndarray:
    data = np.zeros((3, 4, 32, 32), np.float32)
    data[0, :, :16, :16] = 1
    data[1, :, :16, 16:] = 1
    data[2, :, 16:, :16] = 1
    data[:, :, 16:, 16:] = 1
    return data


def closed_form(scene, sub: int = 3):
    """Per pixel: the slab's single scattering (see tests/test_channels.py) and the quadrant
    label of the pixel (-1 near an edge)."""
    cam = camera_frame(scene.camera)
    offs = (np.arange(sub) + 0.5) / sub
    ox, oy = np.meshgrid(offs, offs)
    cols = np.arange(cam.width)[None, :, None] + ox.ravel()[None, None, :]
    rows = np.arange(cam.height)[:, None, None] + oy.ravel()[None, None, :]
    cols, rows = np.broadcast_arrays(cols, rows)
    d = cam.ray_directions(cols.astype(np.float64), rows.astype(np.float64))
    c = np.abs(d[..., 2])
    length = 2 * HALF_THICKNESS / c
    eye = cam.eye.astype(np.float64)
    hit = eye[:2] + ((eye[2] - HALF_THICKNESS) / c)[..., None] * d[..., :2]
    x, y = hit[..., 0], hit[..., 1]
    present = np.stack([(x < 0) & (y < 0) | (x > 0) & (y > 0), (x > 0) & (y < 0) | (x > 0) & (y > 0),
                        (x < 0) & (y > 0) | (x > 0) & (y > 0)], -1).astype(np.float64)
    a = present * np.asarray(OPACITY)
    sigma = SCALE * a.sum(-1)
    rgb = (a[..., None] * np.asarray(COLOURS)).sum(-2) / a.sum(-1)[..., None]
    radiance = (ALBEDO * rgb * IRRADIANCE / (4 * math.pi)
                * ((1 - np.exp(-sigma * (1 + c) * length)) / (1 + c))[..., None]).mean(-2)
    label = np.where(x < 0, 0, 1) + np.where(y < 0, 0, 2)
    edge = (np.abs(x) < 0.07) | (np.abs(y) < 0.07) | (np.abs(x) > 0.43) | (np.abs(y) > 0.43)
    label = np.where(edge, -1, label)
    return radiance, np.where((label == label[..., :1]).all(-1), label[..., 0], -1)


def known_answer(ctx, folder: Path, size: int, spp: int, frames: int) -> dict:
    np.save(folder / "slab.npy", slab())
    channels = [{"transfer_function": {"colors": [[0.0, *col]], "opacity": [[0, 0], [1, a]]}}
                for col, a in zip(COLOURS, OPACITY)]
    scene = parse_scene({"volume": {"path": str(folder / "slab.npy"), "axes": "czyx",
                                    "value_range": [0, 1]},
                         "channels": channels, "density_scale": SCALE, "albedo": ALBEDO,
                         "max_bounces": 1, "environment": [0, 0, 0],
                         "light": {"direction": [0, 0, 1], "irradiance": [IRRADIANCE] * 3},
                         "camera": {"eye": [0, 0, 2.2], "target": [0, 0, 0], "fov_y": 26.0,
                                    "width": size, "height": size},
                         "probes": {"grid": 8 if size < 64 else 32, "samples": 128}})
    want, label = closed_form(scene)
    r = Renderer(ctx, scene)
    out: dict = {"quadrants": ["channel 0", "channel 1", "channel 2", "all three"]}
    try:
        runs = [r.render("pt", spp=spp, seed=s, samples_per_pass=64).image for s in (1, 2)]
        images = {"pt": 0.5 * (runs[0] + runs[1]),
                  "raymarch": r.render("raymarch", spp=frames).image,
                  "probes": r.render("probes", spp=frames).image}
        r.configure(raymarch_stage="fragment")
        images["raymarch-fragment"] = r.render("raymarch", spp=frames).image
    finally:
        r.release()
    for q in range(4):
        sel = label == q
        expected = want[sel].mean(0)
        row = {"pixels": int(sel.sum()), "closed_form": expected.tolist()}
        for name, image in images.items():
            row[name] = (image[sel].mean(0) / expected - 1).tolist()
        row["pt_standard_error"] = (np.abs(runs[0][sel] - runs[1][sel]).mean(0)
                                    / math.sqrt(sel.sum()) / expected).tolist()
        out[str(q)] = row
    return out


def cost(ctx, folder: Path, size: int, cloud_size: int, spp: int, frames: int) -> list[dict]:
    cloud = builtin_cloud((cloud_size,) * 3)
    rows = []
    for count in (1, 2, 3, 4):
        parts = np.zeros((count,) + cloud.shape, np.float32)
        edges = np.linspace(0, cloud_size, count + 1).astype(int)
        for c in range(count):
            parts[c][..., edges[c]:edges[c + 1]] = cloud[..., edges[c]:edges[c + 1]]
        np.save(folder / f"cloud{count}.npy", parts if count > 1 else parts[0])
        tf = {"colors": [[0, 1, 1, 1]], "opacity": [[0, 0], [0.2, 0], [1, 1]]}
        spec = {"volume": {"path": str(folder / f"cloud{count}.npy"), "value_range": [0, 1],
                           **({"axes": "czyx"} if count > 1 else {})},
                "camera": {"width": size, "height": size},
                "probes": {"grid": 4 if cloud_size < 64 else 32, "samples": 64}}
        spec.update({"channels": [{"transfer_function": tf}] * count} if count > 1
                    else {"transfer_function": tf})
        r = Renderer(ctx, parse_scene(spec))
        try:
            r.render("pt", spp=4)                      # compiled, warmed
            pt = r.render("pt", spp=spp, samples_per_pass=16)
            first = r.render("raymarch", spp=1)        # the bake and the light grid
            rm = r.render("raymarch", spp=frames)
            rows.append({"channels": count, "pt_ms_per_sample": pt.render_ms / spp,
                         "raymarch_ms_per_frame": rm.render_ms / frames,
                         "bake_ms": first.bake_ms, "image_mean": float(pt.image.mean())})
        finally:
            r.release()
    return rows


def report(rec: dict) -> str:
    lines = [f"# Channels: known answer and cost ({rec['device']})", "",
             f"Slab of three constant channels at {rec['size']}^2, path tracer {rec['spp']} spp "
             "(two seeds), raymarcher and probes over "
             f"{rec['frames']} frames; relative error of each quadrant's mean per colour (r, g, b):",
             "", "| quadrant | pt (standard error) | raymarch | raymarch-fragment | probes |",
             "|---|---|---|---|---|"]
    ka = rec["known_answer"]
    for q in range(4):
        row = ka[str(q)]
        fmt = lambda v: ", ".join(f"{x:+.3f}" for x in v)  # noqa: E731
        lines.append(f"| {ka['quadrants'][q]} | {fmt(row['pt'])} ({fmt(row['pt_standard_error'])})"
                     f" | {fmt(row['raymarch'])} | {fmt(row['raymarch-fragment'])} | "
                     f"{fmt(row['probes'])} |")
    lines += ["", f"Cost: the built-in cloud ({rec['cloud_size']}^3) split into channels along x "
              "(the same medium in sum):", "",
              "| channels | pt ms / sample | raymarch ms / frame | bake ms |", "|---|---|---|---|"]
    for row in rec["cost"]:
        lines.append(f"| {row['channels']} | {row['pt_ms_per_sample']:.3f} | "
                     f"{row['raymarch_ms_per_frame']:.3f} | {row['bake_ms']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    a = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    a.add_argument("out")
    a.add_argument("--quick", action="store_true", help="llvmpipe: 24^2, 32 spp, a 16^3 cloud")
    a.add_argument("--size", type=int)
    a.add_argument("--spp", type=int)
    args = a.parse_args(argv)
    size = args.size or (24 if args.quick else 512)
    spp = args.spp or (32 if args.quick else 4096)
    frames = 2 if args.quick else 64
    cloud_size = 16 if args.quick else 256
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ctx = create_headless_context()
    with tempfile.TemporaryDirectory() as tmp:
        rec = {"device": describe(ctx), "size": size, "spp": spp, "frames": frames,
               "cloud_size": cloud_size,
               "known_answer": known_answer(ctx, Path(tmp), size, spp, frames),
               "cost": cost(ctx, Path(tmp), size, cloud_size, 4 if args.quick else 256,
                            frames)}
    (out / "results.json").write_text(json.dumps(rec, indent=2) + "\n")
    (out / "report.md").write_text(report(rec))
    print(report(rec))
    return 0


if __name__ == "__main__":
    sys.exit(main())
