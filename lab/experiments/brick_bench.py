"""Issue 33's bricking targets: a 2048^3 uint16 procedural volume written as OME-Zarr on the device
and opened under a 4 GiB cap; and a 20000 x 512 x 512 volume (longer than any
GL_MAX_3D_TEXTURE_SIZE) rendered.

    python lab/experiments/brick_bench.py OUT_DIR [--quick] [--size 2048] [--cap 4G]
        [--width 1920 --height 1080] [--frames 30] [--probes 32] [--long 20000,512,512]
        [--parts write,write-long,capped,progressive,uncapped,zoomed,long,stream] [--reuse]
        [--stores DIR]

1. Writes OUT_DIR/volume.zarr: an OME-Zarr image (levels 0.. each 2x box-filtered, chunks of
   64^3), uint16, a ball of smooth noise in vacuum, slab by slab (never whole in memory); and
   OUT_DIR/long.zarr (one level). Time to write each is recorded.
2. Opens the volume under the cap (RenderSettings.volume_memory_bytes) and records: the level
   shown and its note, the pool's bytes, the time to the first raymarched image (open, range
   pass, upload, light grid, one frame), the raymarcher's 1080p frame rate (FRAMES frames as the
   viewer draws them, each waited for, no readback; GPU ms from timer queries too), the probe
   bake plus light grid time, and where the open's time went (`open_breakdown`: the range
   passes, the upload, its texture writes, the waits for the readers and the readers' reading
   and mapping).
3. rRMSE of that image against the uncapped render (level 0, bricked: no cap). Where level 0 does
   not fit the device, both are rendered over a crop: the central eighth of the box (a quarter of
   each side... half of each side) read as in-memory volumes (level 0's voxels, and the capped
   level's over the same box), the same camera framing it.
   The open again with LabOptions.mixed_levels on (capped_mixed_levels).
4. progressive: the open as the viewer does it (the store's small level drawn as a preview while
   ProgressiveOpen loads the store on a thread; frames drawn meanwhile), timed from opening.
5. zoomed: at a camera near the volume (ZOOMED_EYE), levels mixed by footprint against one whole
   level: first image, frame rate, rRMSE of each against level 0 uncapped.
6. The long volume: bricked (not refused), time to its first raymarched image, and its frame.
7. stream (only when named in --parts): mixed_levels on, opened at the overview camera, the camera
   flown to ZOOMED_EYE in STREAM_STEPS steps; at each the pool restreamed as the viewer does it
   (OPEN_WRITE_BUDGET_S of writes a frame, a raymarched frame drawn between), recording the bricks
   evicted and loaded, the restream's wall seconds, the frames meanwhile and the probes' and
   light grid's bake after its commit; at the end the rRMSE against level 0 as `zoomed` does.

Writes OUT_DIR/results.json (one record a measurement, with the device and the settings) and
OUT_DIR/report.md. --quick: a 48^3 volume, a cap of 12 slots of 8^3 bricks, a 64 x 48 image, a
long volume of GL_MAX_3D_TEXTURE_SIZE + 40 voxels (llvmpipe; tests/test_bricks.py runs it).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from radiance_probes.rendering.metrics import rrmse  # noqa: E402
from radiance_probes.cli.main import memory_size  # noqa: E402
from radiance_probes.gl.context import create_headless_context, describe  # noqa: E402
from radiance_probes.rendering.lab_options import LabOptions  # noqa: E402
from radiance_probes.rendering.renderer import Renderer  # noqa: E402
from radiance_probes.rendering.settings import RenderSettings  # noqa: E402
from radiance_probes.io.scene_file import parse_scene  # noqa: E402
from radiance_probes.io.volume import VolumeError
from radiance_probes.io.load import volume_from_array
from radiance_probes.io.load import load_scene_volume  # noqa: E402


@dataclass(frozen=True)
class Settings:
    size: int = 2048
    cap: int = 4 << 30
    brick: int | None = None          # None: the default (64)
    chunk: int = 64
    width: int = 1920
    height: int = 1080
    frames: int = 30
    probes: int = 32
    probe_samples: int = 64
    long: tuple[int, int, int] = (20000, 512, 512)   # x, y, z


QUICK = Settings(size=48, cap=0, brick=8, chunk=8, width=64, height=48, frames=3, probes=4,
                 probe_samples=16, long=(0, 16, 16))


def density(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The procedural volume at coordinates in [-1, 1] (broadcast): a ball of radius 0.7 with a
    soft edge, modulated by separable waves (cheap at 2048^3), zero outside; in [0, 1]."""
    r2 = x * x + y * y + z * z
    ball = np.clip((0.49 - r2) * 8.0, 0.0, 1.0)
    waves = (0.6 + 0.2 * np.sin(11.0 * x + 1.0) * np.sin(13.0 * y + 2.0)
             + 0.2 * np.sin(17.0 * z + 0.5) * np.cos(7.0 * x))
    return (ball * waves).astype(np.float32)


def _coords(n: int, lo: int, hi: int) -> np.ndarray:
    return ((np.arange(lo, hi, dtype=np.float32) + 0.5) / n * 2.0 - 1.0)


def write_ome_zarr(path: Path, dims, chunk: int, levels: int, value=density) -> float:
    """An OME-Zarr image of `levels` levels (uint16, axes z, y, x), written slab by slab; seconds."""
    import zarr
    from radiance_probes.io.brick_sources import box_filtered
    start = time.perf_counter()
    if path.exists():
        shutil.rmtree(path)
    nx, ny, nz = dims
    root = zarr.open_group(str(path), mode="w", zarr_format=3)
    arrays, shapes = [], []
    for level in range(levels):
        f = 2 ** level
        shape = (-(-nz // f), -(-ny // f), -(-nx // f))
        shapes.append(shape)
        arrays.append(root.create_array(str(level), shape=shape, dtype="uint16",
                                        chunks=tuple(min(chunk, s) for s in shape),
                                        fill_value=0))
    root.attrs["ome"] = {"version": "0.5", "multiscales": [{
        "axes": [{"name": a, "type": "space"} for a in "zyx"],
        "datasets": [{"path": str(level), "coordinateTransformations": [
            {"type": "scale", "scale": [float(2 ** level)] * 3}]} for level in range(levels)]}]}
    # Slabs of level 0 on threads (NumPy and Zarr's encoders run outside the GIL). A level is
    # written by each slab directly where a slab's share of it is whole chunks (no two threads
    # write one chunk); the coarser levels are gathered in memory and written at the end.
    slab = chunk
    direct = [(slab // 2 ** level) % min(chunk, shapes[level][0]) == 0
              and slab % 2 ** level == 0 for level in range(levels)]
    gathered = {level: np.zeros(shapes[level], np.uint16)
                for level in range(levels) if not direct[level]}
    x = _coords(nx, 0, nx)[None, None, :]
    y = _coords(ny, 0, ny)[None, :, None]

    def one(z0: int) -> None:
        z1 = min(z0 + slab, nz)
        zs = _coords(nz, z0, z1)[:, None, None]
        # 8 slices at a time: the function's temporaries stay small (threads x a slab in memory)
        d = np.concatenate([value(x, y, zs[i:i + 8]) for i in range(0, len(zs), 8)])
        for level, array in enumerate(arrays):
            f = 2 ** level
            part = np.round(d * 65535.0).astype(np.uint16)
            if direct[level]:
                array[z0 // f:z0 // f + part.shape[0]] = part
            else:
                gathered[level][z0 // f:z0 // f + part.shape[0]] = part
            d = box_filtered(d)

    from concurrent.futures import ThreadPoolExecutor
    with ThreadPoolExecutor(max(1, min(8, os.cpu_count() or 1))) as pool:
        list(pool.map(one, range(0, nz, slab)))
    for level, data in gathered.items():
        arrays[level][...] = data
    return time.perf_counter() - start


# The zoomed view: the camera near the volume's +z face, where a voxel of level 0 covers up to
# about 3 pixels of a 1080p image (0.3 to 0.5 at the overview's camera).
ZOOMED_EYE = (0.15, 0.25, 0.75)


def _scene(path: Path, s: Settings, crop=None):
    data = {"volume": {"path": str(path), "value_range": [0, 65535]},
            "transfer_function": {"colormap": "viridis",
                                  "opacity": [[0.0, 0.0], [0.3, 0.0], [1.0, 1.0]]},
            "density_scale": 60.0,
            "camera": {"eye": [0.0, 0.4, 2.2], "target": [0, 0, 0], "up": [0, 1, 0],
                       "fov_y": 35.0, "width": s.width, "height": s.height},
            "probes": {"grid": [s.probes] * 3, "samples": s.probe_samples}}
    return parse_scene(data)


def _frames(r: Renderer, s: Settings) -> dict:
    """The raymarcher's frame rate as the viewer draws: each frame a fresh accumulation
    (Renderer.begin) and one sample, waited for (ctx.finish), nothing read back (the image stays
    on the GPU, as the viewer's does). GPU ms from the renderer's timer queries. The frame with
    its 1080p float image read to the host is timed once apart (render(): a script's frame, not
    the viewer's)."""
    ctx = r.ctx
    r.render("raymarch", spp=1, seed=0)          # compiled, light grid baked
    ctx.finish()
    wall, gpu = [], []
    for i in range(s.frames):
        t = time.perf_counter()
        r.begin("raymarch", seed=i + 1)
        gpu.append(r.add_samples(1))
        ctx.finish()
        wall.append(time.perf_counter() - t)
    t = time.perf_counter()
    r.render("raymarch", spp=1, seed=s.frames + 1)
    ctx.finish()
    with_readback = time.perf_counter() - t
    return {"frames": s.frames, "fps": 1.0 / float(np.median(wall)),
            "frame_ms_median": 1e3 * float(np.median(wall)),
            "frame_ms_max": 1e3 * float(np.max(wall)),
            "frame_gpu_ms_median": float(np.median(gpu)),
            "frame_with_readback_ms": 1e3 * with_readback}


def _region(volume, lo: float, hi: float) -> np.ndarray:
    """The densities of a volume (in memory or read brick by brick) over [lo, hi) of each axis
    (fractions of the box)."""
    nx, ny, nz = volume.dims
    a = [int(round(lo * n)) for n in (nz, ny, nx)]
    b = [int(round(hi * n)) for n in (nz, ny, nx)]
    if isinstance(volume.data, np.ndarray):
        return np.array(volume.data[a[0]:b[0], a[1]:b[1], a[2]:b[2]])
    src = volume.data.store.source
    return src.density(src.read(a[0], b[0], a[1], b[1], a[2], b[2]))


PARTS = ("write", "write-long", "capped", "progressive", "uncapped", "zoomed", "long")
KNOWN_PARTS = PARTS + ("stream",)      # stream: only when asked for
# The stream part's camera path: this many steps from the overview to ZOOMED_EYE.
STREAM_STEPS = 10


def _written(path: Path, dims, reuse: bool, chunk: int, levels: int) -> float | None:
    """Seconds to write the store, or None where --reuse found it written (same shape)."""
    if reuse and path.exists():
        import zarr
        try:
            shape = zarr.open_group(str(path), mode="r")["0"].shape
        except Exception:   # not a complete store: written again
            shape = None
        if shape == tuple(dims[::-1]):
            return None
    return write_ome_zarr(path, dims, chunk, levels)


def _need(path: Path) -> Path:
    if not path.exists():
        raise SystemExit(f"{path}: not written yet; run with --parts write (the cube) or "
                         "write-long first (or with it)")
    return path


def run(out: Path, s: Settings, quick: bool, parts=PARTS, reuse: bool = False,
        stores: Path | None = None) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    stores = stores or out
    stores.mkdir(parents=True, exist_ok=True)
    ctx = create_headless_context()
    max_side = int(ctx.info["GL_MAX_3D_TEXTURE_SIZE"])
    old = out / "results.json"
    records: dict = json.loads(old.read_text()) if reuse and old.exists() else {}
    records.update({"device": describe(ctx), "settings": asdict(s), "quick": quick})
    from radiance_probes.io.brick_layout import slot_bytes
    cap = s.cap or 12 * slot_bytes(s.brick, 1, False)
    levels = max(1, int(np.log2(max(s.size // 64, 1))) + 1) if not quick else 3
    path = stores / "volume.zarr"
    long = s.long if not quick else (max_side + 40, s.long[1], s.long[2])
    if "write" in parts:
        written = _written(path, (s.size,) * 3, reuse, s.chunk, levels)
        if written is not None:
            records["write_s"] = written
        records["levels_written"] = levels
    if "write-long" in parts:
        written = _written(stores / "long.zarr", long, reuse, s.chunk, 1)
        if written is not None:
            records["long_write_s"] = written
    scene = _scene(path, s)
    settings = RenderSettings(volume_memory_bytes=cap, brick_size=s.brick)
    if "progressive" in parts:
        _progressive(ctx, records, _scene(_need(path), s), settings, cap)
    if "capped" in parts or "uncapped" in parts:
        _need(path)
        _capped(ctx, records, scene, settings, cap, s, parts)
    if "zoomed" in parts:
        from dataclasses import replace
        zoomed = scene.replace(camera=replace(scene.camera, eye=ZOOMED_EYE))
        _zoomed(ctx, records, _need(path) and zoomed, settings, cap, s)
    if "long" in parts:
        _long(ctx, records, _need(stores / "long.zarr"), s, long)
    if "stream" in parts:
        _stream(ctx, records, _scene(_need(path), s), settings, cap, s)
    (out / "results.json").write_text(json.dumps(records, indent=2))
    _report(out, records, s)
    ctx.release()
    return records


def _open_capped(ctx, records, key, scene, settings, cap, s, mixed: bool = False):
    """Opens the store under the cap with `settings`: the time to the first image, the frame
    rate, bake and light grid; records[key]; returns the shown volume and a 4-spp image."""
    start = time.perf_counter()
    r = Renderer(ctx, scene, settings=settings, lab=LabOptions(mixed_levels=mixed))
    ctx.finish()
    opened = time.perf_counter() - start          # read, range pass, level chosen, uploaded
    first = r.render("raymarch", spp=1, seed=0).image
    ctx.finish()
    shown = r.resources.volume
    pool = r.resources.volume_tex if r.resources.bricked else None
    records[key] = {
        "cap_bytes": cap, "first_image_s": time.perf_counter() - start, "open_s": opened,
        "mixed_levels": mixed,
        "level_dims": list(shown.dims), "notes": list(shown.notes),
        "pool_bytes": int(pool.nbytes) if pool is not None else None,
        "pool_levels": pool.levels if pool is not None else None,
        "resident_bricks": int((pool.brick_of_slot != 0xFFFFFFFF).sum()) if pool is not None
        else None, "bricked": r.resources.bricked, "open_breakdown": _open_breakdown(r),
        **_frames(r, s)}
    r.invalidate()                               # the first image baked them: again, timed
    t = time.perf_counter()
    bake_ms = r.bake(seed=1)
    light_ms = r.bake_light()
    ctx.finish()
    records[key].update(bake_ms=bake_ms, light_ms=light_ms,
                        bake_and_light_wall_s=time.perf_counter() - t,
                        first_image_mean=float(first.mean()))
    image = r.render("raymarch", spp=4, seed=7).image
    r.release()
    return shown, image


def _capped(ctx, records, scene, settings, cap, s, parts):
    # the default settings, then with levels mixed by the camera (LabOptions.mixed_levels
    # on; one whole level where no brick is worth a slot of the finer level)
    from dataclasses import replace
    capped_volume, capped_image = _open_capped(ctx, records, "capped", scene, settings, cap, s)
    _, mixed_image = _open_capped(ctx, records, "capped_mixed_levels", scene, settings, cap, s,
                                  mixed=True)
    records["first_image_mean"] = records["capped"]["first_image_mean"]
    if "uncapped" not in parts:
        return

    # the uncapped render (level 0, bricked), or level 0 against the capped level over a crop
    try:
        r0 = Renderer(ctx, scene, settings=RenderSettings(brick_size=s.brick or 64))
        if r0.resources.volume.dims != (s.size,) * 3:
            raise VolumeError(f"level 0 does not fit: {r0.resources.volume.notes}")
        full = r0.render("raymarch", spp=4, seed=7).image
        full_again = r0.render("raymarch", spp=4, seed=8).image
        r0.release()
        records["rrmse_vs_uncapped"] = {"what": "whole image, level 0 uncapped",
                                        "rrmse": rrmse(capped_image, full),
                                        "rrmse_mixed_levels": rrmse(mixed_image, full),
                                        "rrmse_uncapped_other_seed": rrmse(full_again, full)}
    except VolumeError as exc:
        base = load_scene_volume(scene, s.brick or 64)
        images = []
        for vol in (base, capped_volume):
            region = volume_from_array(_region(vol, 0.25, 0.75), value_range=(0.0, 1.0),
                                       name="crop")
            rc = Renderer(ctx, scene, region, RenderSettings(brick_size=s.brick))
            images.append(rc.render("raymarch", spp=4, seed=7).image)
            rc.release()
        records["rrmse_vs_uncapped"] = {
            "what": "central half of each axis, level 0 against the capped level",
            "why": str(exc), "rrmse": rrmse(images[1], images[0])}


def _zoomed(ctx, records, scene, settings, cap, s):
    """The camera near the volume (ZOOMED_EYE): under the cap with levels mixed by footprint and
    with one whole level, each against level 0 uncapped at the same seeds."""
    from dataclasses import replace
    _, mixed = _open_capped(ctx, records, "zoomed_mixed", scene, settings, cap, s, mixed=True)
    _, whole = _open_capped(ctx, records, "zoomed_whole_level", scene, settings, cap, s)
    r0 = Renderer(ctx, scene, settings=RenderSettings(brick_size=s.brick or 64))
    full = r0.render("raymarch", spp=4, seed=7).image
    again = r0.render("raymarch", spp=4, seed=8).image
    level0 = list(r0.resources.volume.dims)
    r0.release()
    records["zoomed_rrmse_vs_uncapped"] = {
        "eye": list(ZOOMED_EYE), "level0_dims": level0, "rrmse_mixed": rrmse(mixed, full),
        "rrmse_whole_level": rrmse(whole, full), "rrmse_uncapped_other_seed": rrmse(again, full)}


def _stream(ctx, records, scene, settings, cap, s):
    """mixed_levels on, opened at the overview; the camera flown to ZOOMED_EYE in STREAM_STEPS
    steps, each restreamed as the viewer does once the camera settles (Viewer._restream: writes
    of OPEN_WRITE_BUDGET_S a call, a raymarched frame drawn between calls, waited for), then the
    probes and light grid baked again where the mix changed (the viewer does it in slices)."""
    from dataclasses import replace
    from radiance_probes.rendering.levels.progressive_open import OPEN_WRITE_BUDGET_S
    start = time.perf_counter()
    r = Renderer(ctx, scene, settings=settings, lab=LabOptions(mixed_levels=True))
    r.render("raymarch", spp=1, seed=0)
    ctx.finish()
    stream = r.resources.stream
    rec = {"cap_bytes": cap, "first_image_s": time.perf_counter() - start,
           "notes": list(r.resources.volume.notes), "write_budget_s": OPEN_WRITE_BUDGET_S,
           "streamed": stream is not None, "steps": []}
    records["stream"] = rec
    if stream is None:
        r.release()
        return
    rec.update(f_slots=stream.mix.f_slots, c_slots=stream.mix.c_slots,
               capacity=stream.mix.capacity, pool_bytes=int(r.resources.volume_tex.nbytes))
    eye0 = np.asarray(scene.camera.eye, np.float64)
    eye1 = np.asarray(ZOOMED_EYE, np.float64)
    pool = r.resources.volume_tex
    for step in range(1, STREAM_STEPS + 1):
        eye = tuple(float(v) for v in eye0 + (eye1 - eye0) * step / STREAM_STEPS)
        r.set_scene(r.scene.replace(camera=replace(r.scene.camera, eye=eye)))
        uploads, table_writes = pool.uploads, pool.table_writes
        read0 = stream.fine.seconds.get("range_pass")
        frames, frames_gpu, busy, calls, changed = [], [], 0.0, 0, False
        t0 = time.perf_counter()
        while True:
            t = time.perf_counter()
            changed |= r.restream(budget_s=OPEN_WRITE_BUDGET_S)
            busy += time.perf_counter() - t
            calls += 1
            if stream.pending is None:
                break
            t = time.perf_counter()
            r.begin("raymarch", seed=calls)
            frames_gpu.append(r.add_samples(1))
            ctx.finish()
            frames.append(time.perf_counter() - t)
        wall = time.perf_counter() - t0
        t = time.perf_counter()
        bake_ms = r.bake(seed=1) + r.bake_light() if changed else 0.0
        ctx.finish()
        rebake = time.perf_counter() - t
        t = time.perf_counter()
        r.begin("raymarch", seed=0)
        after_gpu = r.add_samples(1)
        ctx.finish()
        after = time.perf_counter() - t
        last = stream.last
        rec["steps"].append({
            "eye": list(eye), "changed": bool(changed), "evicted": last.get("evicted", 0),
            "loaded": last.get("loaded", 0), "worth": last.get("worth", 0),
            "commits": last.get("commits", 0), "resident": stream.resident,
            "restream_wall_s": wall, "restream_calls_s": busy, "calls": calls,
            "bricks_written": pool.uploads - uploads,
            "table_texels_written": pool.table_writes - table_writes,
            "finer_range_pass_s": (stream.fine.seconds.get("range_pass")
                                   if read0 is None else None),
            "frames_meanwhile": len(frames),
            "frame_ms_meanwhile_median": 1e3 * float(np.median(frames)) if frames else None,
            "frame_ms_meanwhile_max": 1e3 * float(np.max(frames)) if frames else None,
            # a frame's GPU time (the raymarched sample, timer queries), and its wall time with
            # the accumulation's restart (begin) and the wait
            "frame_gpu_ms_meanwhile_median": float(np.median(frames_gpu)) if frames_gpu else None,
            "frame_gpu_ms_after": float(after_gpu),
            "rebake_gpu_ms": bake_ms, "rebake_wall_s": rebake, "frame_after_ms": 1e3 * after})
    image = r.render("raymarch", spp=4, seed=7).image
    rec["pool_bytes_end"] = int(r.resources.volume_tex.nbytes)
    r.release()
    r0 = Renderer(ctx, scene.replace(camera=replace(scene.camera, eye=ZOOMED_EYE)),
                  settings=RenderSettings(brick_size=s.brick or 64))
    full = r0.render("raymarch", spp=4, seed=7).image
    rec["level0_dims"] = list(r0.resources.volume.dims)
    r0.release()
    rec["rrmse_vs_level0"] = rrmse(image, full)


def _progressive(ctx, records, scene, settings, cap):
    """The viewer's open (app/viewer/launch.py, Viewer._poll_opening): the store's preview
    (zarr_preview) read and drawn, while ProgressiveOpen loads the store on a thread; each frame
    writes bricks for up to OPEN_WRITE_BUDGET_S and draws the preview's raymarched frame (the
    viewer's frame: begin, one sample, waited for, nothing read back); then the store's own first
    frame. Times from opening."""
    from radiance_probes.rendering.levels.progressive_open import (OPEN_WRITE_BUDGET_S,
                                                                   ProgressiveOpen)
    from radiance_probes.io.load import zarr_preview

    def frame(r, seed, bake=False):
        if bake:        # a new volume: its probes and light grid first (the viewer's first frames)
            r.bake(seed=1)
            r.bake_light()
        r.begin("raymarch", seed=seed)
        r.add_samples(1)
        ctx.finish()

    start = time.perf_counter()
    preview = zarr_preview(scene, memory_bytes=cap)
    preview_read = time.perf_counter() - start
    r = Renderer(ctx, scene, preview, settings=settings)
    opening = ProgressiveOpen(ctx, scene, cap, settings.brick_size,
                              None)   # one whole level (LabOptions.mixed_levels is off)
    frame(r, 0, bake=True)
    preview_image = time.perf_counter() - start
    walls = []
    while True:
        t = time.perf_counter()
        done = opening.poll(OPEN_WRITE_BUDGET_S)
        if done is not None:
            break
        frame(r, len(walls) + 1)
        walls.append(time.perf_counter() - t)
    loaded = time.perf_counter() - start
    given, shown, pool = done
    r.set_scene(scene, given, (shown, pool))
    frame(r, 0, bake=True)
    records["progressive"] = {
        "cap_bytes": cap, "preview_dims": list(preview.dims), "preview_notes": list(preview.notes),
        "preview_read_s": preview_read, "preview_image_s": preview_image,
        "loaded_s": loaded, "first_image_s": time.perf_counter() - start,
        "level_dims": list(shown.dims), "notes": list(shown.notes),
        "frames_while_loading": len(walls),
        "frame_ms_while_loading_median": 1e3 * float(np.median(walls)) if walls else None,
        "frame_ms_while_loading_max": 1e3 * float(np.max(walls)) if walls else None,
        "write_budget_s": OPEN_WRITE_BUDGET_S}
    r.release()


def _open_breakdown(r: Renderer) -> dict:
    """Where the open's time went (app/io/bricks.py BrickStore.seconds, app/gl/brick_pool.py
    BrickPool): wall seconds of level 0's range pass and of the shown level's, of the upload
    (upload_store, all of it) and of its texture writes (with their count); the caller's waits
    for the readers and for the assembling threads; and the seconds the readers spent reading
    and mapping to densities, summed over them (processes or threads: more than wall time)."""
    given = r.resources.given_volume
    shown = r.resources.volume
    pool = r.resources.volume_tex
    level0 = getattr(getattr(given, "bricks", None), "seconds", {})
    store = getattr(getattr(shown, "bricks", None), "seconds", {})
    out = {"level0_range_pass_s": level0.get("range_pass"),
           "shown_range_pass_s": store.get("range_pass") if shown is not given else None,
           "upload_s": getattr(pool, "upload_seconds", None),
           "texture_write_s": getattr(pool, "write_seconds", None),
           "texture_writes": getattr(pool, "writes", None),
           "bricks_written": getattr(pool, "uploads", None),
           "wait_for_readers_s": store.get("upload_read_wait"),
           "wait_for_assembly_s": store.get("upload_assembly_wait"),
           "readers_read_s_summed": store.get("upload_read"),
           "readers_map_s_summed": store.get("upload_map"),
           # layers from the reading processes: in shared memory, or pickled (a /dev/shm too
           # small for them; none from threads)
           "layers_handed": dict(getattr(getattr(shown, "bricks", None), "handed", {}))}
    return out


def _long(ctx, records, lpath, s, long):
    max_side = int(ctx.info["GL_MAX_3D_TEXTURE_SIZE"])
    start = time.perf_counter()
    rl = Renderer(ctx, _scene(lpath, s), settings=RenderSettings(brick_size=s.brick))
    image = rl.render("raymarch", spp=1, seed=0).image
    ctx.finish()
    records["long"] = {"dims": list(long), "max_3d_texture_size": max_side,
                       "bricked": rl.resources.bricked,
                       "level_dims": list(rl.resources.volume.dims),
                       "first_image_s": time.perf_counter() - start,
                       "finite": bool(np.isfinite(image).all()),
                       "mean_radiance": float(image.mean()), **_frames(rl, s)}
    rl.release()


def _report(out: Path, records: dict, s: Settings) -> None:
    lines = [f"# Bricked volumes ({records['device']})", ""]
    c, lg, err = records.get("capped"), records.get("long"), records.get("rrmse_vs_uncapped")
    if c:
        lines.append(
            f"- {s.size}^3 uint16 under a {c['cap_bytes'] / 2**30:.2f} GiB cap: level "
            f"{c['level_dims']}, first image {c['first_image_s']:.1f} s, raymarched "
            f"{s.width}x{s.height} {c['fps']:.1f} fps, bake {c['bake_ms']:.0f} ms + light grid "
            f"{c['light_ms']:.0f} ms ({c['bake_and_light_wall_s']:.1f} s wall)")
        lines.append(f"- notes: {'; '.join(c['notes']) or 'none'}")
        b = c.get("open_breakdown") or {}

        def sec(key):
            return "-" if b.get(key) is None else f"{b[key]:.2f} s"
        lines.append(
            f"- the open: range pass level 0 {sec('level0_range_pass_s')}, shown level "
            f"{sec('shown_range_pass_s')}; upload {sec('upload_s')} (texture writes "
            f"{sec('texture_write_s')} in {b.get('texture_writes')} writes of "
            f"{b.get('bricks_written')} bricks; waiting for the readers "
            f"{sec('wait_for_readers_s')}, for the assembly {sec('wait_for_assembly_s')}; the "
            f"readers' reading {sec('readers_read_s_summed')} and mapping "
            f"{sec('readers_map_s_summed')}, summed over them; layers from the reading "
            f"processes {b.get('layers_handed')})")
    pg = records.get("progressive")
    if pg:
        lines.append(
            f"- opened as the viewer opens it: preview {pg['preview_dims']} drawn after "
            f"{pg['preview_image_s']:.1f} s; level {pg['level_dims']} drawn after "
            f"{pg['first_image_s']:.1f} s; {pg['frames_while_loading']} frames meanwhile "
            f"(median {pg['frame_ms_while_loading_median'] or 0:.0f} ms, longest "
            f"{pg['frame_ms_while_loading_max'] or 0:.0f} ms)")
    w = records.get("capped_mixed_levels")
    if w:
        lines.append(f"- mixed_levels on: {w['notes'][-1] if w['notes'] else ''}; first image "
                     f"{w['first_image_s']:.1f} s, {w['fps']:.1f} fps")
    if err:
        lines.append(f"- rRMSE against level 0: {err['rrmse']:.4f} ({err['what']})"
                     + (f"; mixed_levels on {err['rrmse_mixed_levels']:.4f}; level 0 against "
                        f"itself at another seed {err['rrmse_uncapped_other_seed']:.4f}"
                        if "rrmse_mixed_levels" in err else ""))
    zm, zw, ze = (records.get(k) for k in ("zoomed_mixed", "zoomed_whole_level",
                                            "zoomed_rrmse_vs_uncapped"))
    if zm and zw and ze:
        lines.append(
            f"- zoomed (eye {ze['eye']}): levels mixed: {zm['notes'][-1] if zm['notes'] else ''}; "
            f"first image {zm['first_image_s']:.1f} s, {zm['fps']:.1f} fps, rRMSE against "
            f"level 0 {ze['rrmse_mixed']:.4f}; one whole level: first image "
            f"{zw['first_image_s']:.1f} s, {zw['fps']:.1f} fps, rRMSE {ze['rrmse_whole_level']:.4f}"
            f"; level 0 against itself at another seed {ze['rrmse_uncapped_other_seed']:.4f}")
    st = records.get("stream")
    if st and st.get("steps"):
        steps = st["steps"]
        lines.append(
            f"- stream (mixed_levels, overview to zoomed in {len(steps)} steps, {st['f_slots']} "
            f"slots for the finer level): loaded {[x['loaded'] for x in steps]}, evicted "
            f"{[x['evicted'] for x in steps]}, restream wall s "
            f"{[round(x['restream_wall_s'], 2) for x in steps]}, frames meanwhile median ms "
            f"{[None if x['frame_ms_meanwhile_median'] is None else round(x['frame_ms_meanwhile_median'], 1) for x in steps]}"
            f" (wall, the accumulation's restart included), a frame's GPU ms after each step "
            f"{[round(x.get('frame_gpu_ms_after', float('nan')), 1) for x in steps]}"
            f"; rRMSE against level 0 at the end {st['rrmse_vs_level0']:.4f}")
    elif st:
        lines.append(f"- stream: no mixed pool ({'; '.join(st['notes'])})")
    if lg:
        lines.append(f"- long volume {lg['dims']}: bricked {lg['bricked']}, first image "
                     f"{lg['first_image_s']:.1f} s, {lg['fps']:.1f} fps")
    (out / "report.md").write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out")
    p.add_argument("--quick", action="store_true")
    p.add_argument("--size", type=int)
    p.add_argument("--cap", type=memory_size)
    p.add_argument("--width", type=int)
    p.add_argument("--height", type=int)
    p.add_argument("--frames", type=int)
    p.add_argument("--probes", type=int)
    p.add_argument("--long", type=lambda t: tuple(int(v) for v in t.split(",")))
    p.add_argument("--parts", type=lambda t: tuple(t.split(",")), default=PARTS,
                   help="which parts: write,write-long,capped,progressive,uncapped,zoomed,long,"
                        "stream (default all but stream)")
    p.add_argument("--reuse", action="store_true",
                   help="keep stores already written (same shape) and add to results.json")
    p.add_argument("--stores", type=Path,
                   help="where the Zarr stores are written (default OUT_DIR)")
    args = p.parse_args(argv)
    unknown = set(args.parts) - set(KNOWN_PARTS)
    if unknown:
        p.error(f"--parts: unknown {', '.join(sorted(unknown))} (known: "
                f"{', '.join(KNOWN_PARTS)})")
    s = QUICK if args.quick else Settings()
    changes = {k: v for k, v in vars(args).items()
               if k not in ("out", "quick", "parts", "reuse", "stores") and v is not None}
    from dataclasses import replace
    s = replace(s, **changes)
    run(Path(args.out), s, args.quick, args.parts, args.reuse, args.stores)
    return 0


if __name__ == "__main__":
    sys.exit(main())
