"""Large volumes on the GPU (issue 13.4): a 512^3 uint16 CT-like volume and a 1024x1024x512 uint16
one, written as .npy, loaded, path traced and raymarched over probes at 512^2, with the GPU memory
they take (the NVIDIA driver's query before and after) and the times; then a volume one voxel
longer than GL_MAX_3D_TEXTURE_SIZE, which must be refused with a message that says why.
Usage: python lab/experiments/large_volumes.py OUT.json   (the H100 run: bench/h100-large/results.json)"""
from __future__ import annotations

import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from radiance_probes.gl.context import create_headless_context, describe
from radiance_probes.gl.memory import gpu_available_bytes
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.scene.types import VolumeError
from radiance_probes.io.load import load_scene_volume


def ct_like(shape_zyx: tuple[int, int, int]) -> np.ndarray:
    """Hounsfield-like uint16 (stored + 1024): air, a soft-tissue body, bone shells, noise."""
    z, y, x = (np.linspace(-1, 1, n, dtype=np.float32) for n in shape_zyx)
    out = np.empty(shape_zyx, np.uint16)
    rng = np.random.default_rng(0)
    for k in range(shape_zyx[0]):          # a slice at a time: 1024x1024x512 is 512M voxels
        r = np.sqrt(x[None, :] ** 2 + (1.3 * y[:, None]) ** 2 + 0.2 * z[k] ** 2)
        hu = np.where(r < 0.8, 40.0, -1000.0)
        hu = np.where((r > 0.6) & (r < 0.66), 900.0, hu)                       # a bone shell
        hu += rng.normal(0, 20, hu.shape).astype(np.float32)
        out[k] = np.clip(hu + 1024, 0, 4095).astype(np.uint16)
    return out


def main() -> int:
    out_path = Path(sys.argv[1])
    ctx = create_headless_context()
    records = {"meta": {"device": describe(ctx), "command": " ".join(sys.argv),
                        "max_3d_texture": int(ctx.info["GL_MAX_3D_TEXTURE_SIZE"])}, "records": []}
    with tempfile.TemporaryDirectory() as t:
        for shape in ((512, 512, 512), (512, 1024, 1024)):
            path = Path(t) / f"ct_{shape[2]}x{shape[1]}x{shape[0]}.npy"
            t0 = time.time()
            np.save(path, ct_like(shape))
            made_s = time.time() - t0
            scene = parse_scene({"volume": {"path": str(path), "value_range": [824, 2024]},
                                 "transfer_function": {"colormap": "coolwarm"},
                                 "density_scale": 60.0, "camera": {"width": 512, "height": 512},
                                 "probes": {"grid": [64, 64, 64], "samples": 256}})
            free0 = gpu_available_bytes(ctx)
            t0 = time.time()
            volume = load_scene_volume(scene)
            r = Renderer(ctx, scene, volume)
            load_s = time.time() - t0
            pt = r.render("pt", spp=16, seed=1, samples_per_pass=16)
            rm = r.render("raymarch", spp=1, seed=1)
            free1 = gpu_available_bytes(ctx)
            rec = {"dims": list(volume.dims), "dtype": volume.raw_dtype, "file_mib": path.stat().st_size / 2**20,
                   "made_s": made_s, "load_and_upload_s": load_s,
                   "gpu_mib_used": None if free0 is None or free1 is None else (free0 - free1) / 2**20,
                   "volume_texture_mib": volume.data.size * (2 if volume.exact_uint8 else 4) / 2**20,
                   "light_grid": list(r._light.texture.size), "probe_grid": list(r.probe_grid.grid),
                   "pt_16spp_ms": pt.render_ms, "pt_ms_per_spp": pt.render_ms / 16,
                   "bake_and_light_ms": rm.bake_ms, "raymarch_frame_ms": rm.render_ms,
                   "stats": pt.stats}
            print(json.dumps(rec), flush=True)
            records["records"].append(rec)
            r.release()
            del volume
            path.unlink()
        side = records["meta"]["max_3d_texture"] + 1
        path = Path(t) / "too_long.npy"
        np.save(path, np.zeros((4, 4, side), np.uint8) + 7)
        scene = parse_scene({"volume": {"path": str(path)}})
        try:
            r = Renderer(ctx, scene, load_scene_volume(scene))
            r.release()
            refusal = "NOT refused"
        except VolumeError as exc:
            refusal = str(exc)
        print("refusal:", refusal, flush=True)
        records["refusal"] = {"dims": [side, 4, 4], "message": refusal}
    out_path.write_text(json.dumps(records, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
