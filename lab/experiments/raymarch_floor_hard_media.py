"""What sets the raymarcher's error floor on hard media (issue 56, item 4)? The stress battery's
backlit thin shell (app/bench/scenes.py `shell-g06`: albedo 0.99, g = 0.6, the sun behind the
shell seen from the default camera, max_bounces 256), its volume at --side voxels with the density
scaled by side / 128 so the shell keeps the bench's optical thickness (it is about two voxels thick
at any side). The raymarcher (`raymarch`) against a converged path-traced reference (`pt`, two
independent halves: their difference is the reference's own noise), one factor at a time from a
baseline (16^3 probes x 256 walks, SH order 2, the GPU's default light grid: 128 texels a side
here, raymarch step 0.5 voxel, seed 11):

  (a) the probe grid 8^3 / 16^3 / 32^3;
  (b) walks per probe 64 / 256 / 1024, and a second bake seed (probe noise directly);
  (c) the SH truncation: order 3 (sun lobe off and on) and 4 at g = 0.6; g = 0.0 and 0.9 scenes
      at the baseline (each with its own reference);
  (d) the light grid (the direct sun term) 24 / 48 / 96 / 128 / 256 texels a side, with the
      walks' sun from shadow rays (walk_sun "ray": the probes then do not read the light grid,
      so one bake serves every light grid and only the image's direct term changes);
  (e) the raymarch step 1.0 / 0.5 / 0.25 / 0.125 voxel (read-side: the same probes);
  combo: the 256-texel light grid alone and with 4x the walks or 2x the probes per axis;
  and the split into single scattering (max_bounces 1, the sun from the light grid, against a
  single-scattering path trace) and the rest (all bounces minus single scattering, i.e. what the
  probes carry): each one's RMS error relative to the full reference's RMS.

Every variant is baked with each of --seeds (11, 12: independent bakes and frame seeds); a row
gives the RMS over seeds of each error and, from the image averaged over the bakes, an estimate of
the systematic part (what more walks or frames would not take away; two seeds make it rough).
Per row: rRMSE (and corrected for the reference's noise, metrics.corrected_rrmse), block rRMSE
over 8 and 16 px tiles (metrics.block_rrmse), the image mean ratio raymarch / pt, bake and
wall times.

    PYTHONPATH=<dir holding radiance_probes> python lab/experiments/raymarch_floor_hard_media.py \
        OUT.json [--size 48] [--side 48] [--ref-spp 8192] [--frames 16] [--blocks a,b,...] [--quick]

--size is the image width (height 3/4 of it); --ref-spp is per half of each reference. The
llvmpipe run (docs/raymarch_floor.md) used the defaults: every block but combo (16 min), then
--blocks combo (9 min); all blocks at once take about 22 min there. On a GPU, e.g. --size 256
--side 128 --ref-spp 65536. --quick: a smoke test (seconds).
"""
from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import radiance_probes.rendering.grids.light_transmittance as light_module  # noqa: E402
from radiance_probes.bench.scenes import BATTERY  # noqa: E402
from radiance_probes.gl.context import create_headless_context, describe  # noqa: E402
from radiance_probes.io.scene_file import parse_scene  # noqa: E402
from radiance_probes.rendering.metrics import (block_rrmse, corrected_rrmse,  # noqa: E402
                                               reference_noise, rrmse)
from radiance_probes.rendering.renderer import Renderer  # noqa: E402

BLOCKS = ("base", "grid", "walks", "sh", "g", "light", "step", "single", "combo")
parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
parser.add_argument("out")
parser.add_argument("--size", type=int, default=48, help="image width (height 3/4 of it)")
parser.add_argument("--side", type=int, default=48, help="the shell volume's side in voxels")
parser.add_argument("--ref-spp", type=int, default=8192, help="path-traced spp per reference half")
parser.add_argument("--ss-ref-spp", type=int, default=None,
                    help="spp per half of the single-scattering reference (default: --ref-spp / 4)")
parser.add_argument("--other-ref-spp", type=int, default=None,
                    help="spp per half of the g = 0 and 0.9 references (default: --ref-spp / 2)")
parser.add_argument("--frames", type=int, default=128, help="raymarched frames an image")
parser.add_argument("--seeds", default="11,12", help="bake seeds of every variant")
parser.add_argument("--grid", type=int, default=16, help="baseline probes per axis")
parser.add_argument("--walks", type=int, default=256, help="baseline walks per probe")
parser.add_argument("--grids", default="8,32", help="probe grids besides the baseline's")
parser.add_argument("--walk-counts", default="64,1024", help="walks besides the baseline's")
parser.add_argument("--light-sides", default="24,48,96,128,256", help="light grid sides")
parser.add_argument("--steps", default="1.0,0.25,0.125", help="raymarch steps besides 0.5")
parser.add_argument("--blocks", default=",".join(BLOCKS), help="which sweeps: " + ",".join(BLOCKS))
parser.add_argument("--quick", action="store_true", help="smoke test: tiny sizes")
args = parser.parse_args()
if args.quick:
    args.size, args.side, args.ref_spp, args.frames = 16, 16, 256, 4
    args.grid, args.walks, args.grids, args.walk_counts = 4, 32, "2", "16"
    args.light_sides, args.steps = "8,16,128", "1.0"
blocks = set(args.blocks.split(","))
W, H = args.size, max(8, round(args.size * 3 / 4))
SEEDS = tuple(int(v) for v in args.seeds.split(","))
ss_ref_spp = args.ss_ref_spp or max(64, args.ref_spp // 4)

ctx = create_headless_context()
device = describe(ctx)
print(device, flush=True)
t_start = time.time()


def make_scene(g: float = 0.6, grid: int | None = None, walks: int | None = None,
               order: int = 2, max_bounces: int | None = None):
    spec = copy.deepcopy(BATTERY["shell-g06"])
    spec["volume"]["size"] = [args.side] * 3
    spec["density_scale"] = spec["density_scale"] * args.side / 128.0
    spec["anisotropy"] = g
    if max_bounces is not None:
        spec["max_bounces"] = max_bounces
    spec["camera"] = {"width": W, "height": H}
    n = grid or args.grid
    spec["probes"] = {"grid": [n, n, n], "samples": walks or args.walks, "sh_order": order}
    return parse_scene(spec)


def gpu_defaults(r: Renderer) -> None:
    """The light grid as a GPU makes it (llvmpipe's default keeps the volume's resolution):
    at least 128 texels, following the probes (12 a probe spacing), at most twice the volume's."""
    r.configure(light_follows_probes=True, light_min_side=light_module.MIN_SIDE,
                light_max_side=light_module.MAX_SIDE)


def set_light_side(r: Renderer, side: int) -> None:
    """A light grid of `side` texels along the (cubic) volume's axes: below the GPU default by
    capping its side, above it by letting it upsample the volume further."""
    if side <= light_module.MIN_SIDE:
        light_module.VOLUME_UPSAMPLING = 2
        r.configure(light_follows_probes=False, light_min_side=side, light_max_side=side)
    else:
        light_module.VOLUME_UPSAMPLING = -(-side // args.side)
        r.configure(light_follows_probes=False, light_min_side=side, light_max_side=side)


def lum_mean(img):
    return float(np.asarray(img, np.float64).mean())


def tiles(a, block):
    a = np.asarray(a, np.float64)
    h, w = (a.shape[0] // block) * block, (a.shape[1] // block) * block
    return a[:h, :w].reshape(h // block, block, w // block, block, -1).mean(axis=(1, 3))


def reference(r: Renderer, spp: int, label: str) -> dict:
    t = time.time()
    halves = [r.render("pt", spp=spp, seed=s, samples_per_pass=16).image.astype(np.float64)
              for s in (1000003, 2000003)]
    ref = 0.5 * (halves[0] + halves[1])
    noise = {"pixel": reference_noise(*halves)}
    for b in (8, 16):
        if min(W, H) >= b:
            noise[f"block{b}"] = reference_noise(tiles(halves[0], b), tiles(halves[1], b))
    rec = dict(label=label, spp=2 * spp, mean=lum_mean(ref), noise=noise, wall_s=time.time() - t)
    print(f"reference {label}: {2 * spp} spp, mean {rec['mean']:.5f}, noise pixel "
          f"{noise['pixel']:.2%} " + " ".join(f"{k} {v:.2%}" for k, v in noise.items()
                                               if k != "pixel")
          + f" ({rec['wall_s']:.0f} s)", flush=True)
    return dict(image=ref, halves=halves, noise=noise, record=rec)


rows: list[dict] = []
refs: dict[str, dict] = {}
images: dict[str, dict[int, np.ndarray]] = {}   # label -> seed -> image


def score(img, ref: dict) -> dict:
    """rRMSE (and corrected for the reference's noise), block rRMSE over 8 and 16 px tiles (and
    corrected), image mean ratio against one reference."""
    out = dict(rrmse=rrmse(img, ref["image"]),
               mean_ratio=lum_mean(img) / lum_mean(ref["image"]))
    out["rrmse_corrected"] = corrected_rrmse(out["rrmse"], ref["noise"]["pixel"])
    for b in (8, 16):
        if min(W, H) >= b:
            out[f"block{b}"] = block_rrmse(img, ref["image"], b)
            out[f"block{b}_corrected"] = corrected_rrmse(out[f"block{b}"],
                                                         ref["noise"][f"block{b}"])
    return out


def signed_sqrt(v: float) -> float:
    return float(np.sign(v) * np.sqrt(abs(v)))


def combine(block: str, label: str, ref_key: str, per_seed: list[dict], imgs: list) -> dict:
    """One row from the images of independent bakes (seeds): the RMS over seeds of each error,
    the mean ratio's mean, and with two bakes or more the error of their mean and the systematic
    part: E[e_1^2] = b^2 + n^2 and E[e_mean^2] = b^2 + n^2 / k over k independent bakes (each
    with its own frame seeds), so b^2 = (k e_mean^2 - mean(e_1^2)) / (k - 1) (corrected errors,
    signed root)."""
    ref = refs[ref_key]
    metrics = [m for m in ("rrmse_corrected", "block8_corrected", "block16_corrected")
               if m in per_seed[0]]
    row = dict(block=block, label=label, reference=ref_key, seeds=[p["seed"] for p in per_seed])
    for m in ("rrmse", "rrmse_corrected", "block8", "block8_corrected", "block16",
              "block16_corrected"):
        if m in per_seed[0]:
            row[m] = float(np.sqrt(np.mean([p[m] ** 2 for p in per_seed])))
            row[m + "_per_seed"] = [p[m] for p in per_seed]
    row["mean_ratio"] = float(np.mean([p["mean_ratio"] for p in per_seed]))
    row["mean_ratio_per_seed"] = [p["mean_ratio"] for p in per_seed]
    k = len(imgs)
    if k >= 2:
        mean_img = sum(imgs) / k
        sm = score(mean_img, ref)
        row["mean_of_bakes"] = {m: sm[m] for m in sm}
        for m in metrics:
            base = m.replace("_corrected", "")
            e1 = np.mean([p[m] ** 2 * np.sign(p[m]) for p in per_seed])
            row["systematic_" + base] = signed_sqrt(
                (k * sm[m] ** 2 * np.sign(sm[m]) - e1) / (k - 1))
        row["between_bakes_rrmse_over_sqrt2"] = rrmse(imgs[0], imgs[1]) / np.sqrt(2.0)
    for key in ("probes", "sh_order", "sun_lobe_g", "light_grid", "raymarch_step", "walk_sun",
                "frames"):
        row[key] = per_seed[0][key]
    row["bake_ms"] = [p["bake_ms"] for p in per_seed]
    row["wall_s"] = float(sum(p["wall_s"] for p in per_seed))
    rows.append(row)
    images[label] = dict(zip(row["seeds"], imgs))
    sys_txt = "".join(f" sys{m.replace('_corrected', '').replace('rrmse', '')} "
                      f"{row['systematic_' + m.replace('_corrected', '')]:7.2%}"
                      for m in metrics if "systematic_" + m.replace("_corrected", "") in row)
    print(f"{block:6s} {label:40s} rRMSE {row['rrmse']:6.2%} (corr {row['rrmse_corrected']:6.2%})"
          + "".join(f" blk{b} {row[f'block{b}']:6.2%}" for b in (8, 16) if f"block{b}" in row)
          + sys_txt + f" mean {row['mean_ratio']:.3f} ["
          + ",".join(f"{v:.3f}" for v in row["mean_ratio_per_seed"]) + "]"
          + f" light {row['light_grid'][0] if row['light_grid'] else None}"
          f" bake {np.mean(row['bake_ms']) / 1e3:.1f} s wall {row['wall_s']:.0f} s", flush=True)
    return row


def render_one(r: Renderer, ref_key: str, seed: int, rebake: bool,
               frames: int | None = None) -> tuple[dict, np.ndarray]:
    """The raymarched image of the current scene and settings (rebake: the probes baked again
    with `seed` even where they are current), scored against refs[ref_key]."""
    t = time.time()
    if rebake:
        r.forget_probes()
    n = frames or args.frames
    res = r.render("raymarch", spp=n, seed=seed, samples_per_pass=min(n, 64))
    img = res.image.astype(np.float64)
    light = r._light
    rec = dict(seed=seed, **score(img, refs[ref_key]),
               probes=f"{r.scene.probes.grid[0]}^3 x {r.scene.probes.samples}",
               sh_order=r.probe_grid.sh_order if r.probe_grid is not None else None,
               sun_lobe_g=getattr(r.probe_grid, "sun_lobe", None),
               light_grid=list(light.grid) if light is not None else None,
               raymarch_step=r.settings.raymarch_step, walk_sun=r.settings.walk_sun,
               frames=n, bake_ms=res.bake_ms, wall_s=time.time() - t)
    return rec, img


def bake_variant(r: Renderer, block: str, label: str, ref_key: str, frames: int | None = None):
    """A variant that changes the bake: each seed's probes baked anew."""
    recs, imgs = zip(*(render_one(r, ref_key, s, True, frames) for s in SEEDS))
    return combine(block, label, ref_key, list(recs), list(imgs))


def read_variants(r: Renderer, block: str, ref_key: str, variants: list):
    """Variants (label, setup) that read the same probes (read-side, or a light grid the walks
    do not read): per seed one bake, then every variant on it."""
    got = {label: ([], []) for label, _ in variants}
    for s in SEEDS:
        for i, (label, setup) in enumerate(variants):
            setup()
            if i > 0 and not r.probes_current():
                raise RuntimeError(f"{label}: the probes would be baked again")
            rec, img = render_one(r, ref_key, s, rebake=(i == 0))
            got[label][0].append(rec)
            got[label][1].append(img)
    return [combine(block, label, ref_key, *got[label]) for label, _ in variants]


def with_probes(r: Renderer, **changes) -> None:
    r.set_scene(r.scene.replace(probes=replace(r.scene.probes, **changes)))


# ---- g = 0.6: the baseline and every sweep at that anisotropy ---------------------------------
r = Renderer(ctx, make_scene(0.6))
gpu_defaults(r)
refs["g0.6"] = reference(r, args.ref_spp, "g0.6")
bake_variant(r, "base", "baseline", "g0.6")
if "base" in blocks:
    bake_variant(r, "base", f"baseline, {4 * args.frames} frames", "g0.6", frames=4 * args.frames)

if "grid" in blocks:
    for n in (int(v) for v in args.grids.split(",") if v):
        with_probes(r, grid=(n, n, n))
        bake_variant(r, "grid", f"probes {n}^3 x {args.walks}", "g0.6")
    with_probes(r, grid=(args.grid,) * 3)

if "walks" in blocks:
    for w in (int(v) for v in args.walk_counts.split(",") if v):
        with_probes(r, samples=w)
        bake_variant(r, "walks", f"probes {args.grid}^3 x {w}", "g0.6")
    with_probes(r, samples=args.walks)

if "sh" in blocks:
    r.configure(sun_lobe=False)
    with_probes(r, sh_order=3)
    bake_variant(r, "sh", "SH order 3, no sun lobe", "g0.6")
    r.configure(sun_lobe=True)
    bake_variant(r, "sh", "SH order 3 + sun lobe (auto's pick)", "g0.6")
    with_probes(r, sh_order=4)
    bake_variant(r, "sh", "SH order 4", "g0.6")
    with_probes(r, sh_order=2)


def step_setter(step):
    return lambda: r.configure(raymarch_step=step)


if "step" in blocks:
    steps = [0.5] + [float(v) for v in args.steps.split(",") if v]
    read_variants(r, "step", "g0.6", [(f"step {st}", step_setter(st)) for st in steps])
    r.configure(raymarch_step=0.5)


def light_setter(rr, side):
    return lambda: set_light_side(rr, side)


if "light" in blocks:
    r.configure(walk_sun="ray")
    sides = [int(v) for v in args.light_sides.split(",") if v]
    read_variants(r, "light", "g0.6", [(f"light grid {side}, walks' sun by ray",
                                        light_setter(r, side)) for side in sides])
    light_module.VOLUME_UPSAMPLING = 2
    r.configure(walk_sun="grid")
    gpu_defaults(r)

if "combo" in blocks:
    # what lowers the floor together: the finest light grid with more walks or more probes (the
    # walks' sun from that grid, corrected, as the product does)
    set_light_side(r, 256)
    bake_variant(r, "combo", "light grid 256 (walks read it)", "g0.6")
    with_probes(r, samples=4 * args.walks)
    bake_variant(r, "combo", f"light grid 256 + {args.grid}^3 x {4 * args.walks}", "g0.6")
    with_probes(r, samples=args.walks, grid=(2 * args.grid,) * 3)
    bake_variant(r, "combo", f"light grid 256 + {2 * args.grid}^3 x {args.walks}", "g0.6")
    with_probes(r, grid=(args.grid,) * 3)
    light_module.VOLUME_UPSAMPLING = 2
    gpu_defaults(r)

if "single" in blocks:
    ss = Renderer(ctx, make_scene(0.6, max_bounces=1))
    gpu_defaults(ss)
    ss.configure(walk_sun="ray")   # one bake a seed for every light grid
    refs["g0.6-ss"] = reference(ss, ss_ref_spp, "g0.6 single scattering")

    def ss_default():
        gpu_defaults(ss)
        light_module.VOLUME_UPSAMPLING = 2
        ss.configure(raymarch_step=0.5)

    def ss_step():
        ss_default()
        ss.configure(raymarch_step=0.125)
    read_variants(ss, "single", "g0.6-ss", [
        ("single scattering (max_bounces 1)", ss_default),
        ("single scattering, light grid 48", light_setter(ss, 48)),
        ("single scattering, light grid 256", light_setter(ss, 256)),
        ("single scattering, step 0.125", ss_step)])
    ss_default()
    ss.release()
    # the baseline's error split per seed: single scattering, and the rest (what the probes
    # carry: all bounces minus single scattering)
    full, ssr = refs["g0.6"]["image"], refs["g0.6-ss"]["image"]
    norm = np.sqrt(np.mean(full ** 2))
    split = []
    for s in SEEDS:
        rm, rm_ss = images["baseline"][s], images["single scattering (max_bounces 1)"][s]
        split.append(dict(
            seed=s, single_error_over_full_rms=float(np.sqrt(np.mean((rm_ss - ssr) ** 2)) / norm),
            rest_error_over_full_rms=float(
                np.sqrt(np.mean(((rm - rm_ss) - (full - ssr)) ** 2)) / norm),
            rest_mean_ratio=float((rm - rm_ss).mean() / (full - ssr).mean()),
            single_mean_ratio=float(rm_ss.mean() / ssr.mean())))
    rows.append(dict(block="single", label="baseline split", reference="g0.6",
                     single_share_of_reference_mean=float(ssr.mean() / full.mean()),
                     per_seed=split))
    for p in split:
        print(f"single split seed {p['seed']}: single scattering {ssr.mean() / full.mean():.1%} of"
              f" the image mean; its error {p['single_error_over_full_rms']:.2%} (mean ratio "
              f"{p['single_mean_ratio']:.3f}), the rest's {p['rest_error_over_full_rms']:.2%} "
              f"(mean ratio {p['rest_mean_ratio']:.3f}) of the full image's RMS", flush=True)
r.release()

if "g" in blocks:
    for g in (0.0, 0.9):
        rg = Renderer(ctx, make_scene(g))
        gpu_defaults(rg)
        refs[f"g{g}"] = reference(rg, args.other_ref_spp or args.ref_spp // 2, f"g{g}")
        bake_variant(rg, "g", f"g = {g} baseline (SH order 2)", f"g{g}")
        if g == 0.9:
            rg.configure(sun_lobe=True)
            with_probes(rg, sh_order=3)
            bake_variant(rg, "g", "g = 0.9, SH order 3 + sun lobe", f"g{g}")
        rg.release()

out = dict(meta=dict(device=device, command=" ".join(sys.argv), image=[W, H], side=args.side,
                     ref_spp_per_half=args.ref_spp, ss_ref_spp_per_half=ss_ref_spp,
                     other_ref_spp_per_half=args.other_ref_spp or args.ref_spp // 2,
                     frames=args.frames, seeds=list(SEEDS),
                     baseline=dict(grid=args.grid, walks=args.walks, sh_order=2,
                                   raymarch_step=0.5, light="GPU default (128 texels here)"),
                     wall_s=time.time() - t_start),
           references={k: v["record"] for k, v in refs.items()}, rows=rows)
Path(args.out).write_text(json.dumps(out, indent=1))

print("\nRMS over seeds; sys: the systematic part (bias) from the mean of the bakes; mean: "
      "raymarch / pt")
print("| block | variant | rRMSE (corr) | block8 (corr) | block16 (corr) | sys pixel | sys block16 |"
      " mean rm/pt | bake s |")
print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
nan = float("nan")
for row in rows:
    if "rrmse" not in row:
        continue
    print(f"| {row['block']} | {row['label']} | {row['rrmse']:.2%} ({row['rrmse_corrected']:.2%}) |"
          f" {row.get('block8', nan):.2%} ({row.get('block8_corrected', nan):.2%}) |"
          f" {row.get('block16', nan):.2%} ({row.get('block16_corrected', nan):.2%}) |"
          f" {row.get('systematic_rrmse', nan):.2%} | {row.get('systematic_block16', nan):.2%} |"
          f" {row['mean_ratio']:.3f} | {np.mean(row['bake_ms']) / 1e3:.1f} |")
print(f"total wall {time.time() - t_start:.0f} s; wrote {args.out}")
