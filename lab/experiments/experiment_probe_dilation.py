"""Probe dilation against leaks: probes whose cell is optically thick (sigma_t at the probe x the
probe spacing > T) take the mean of their thin neighbours (26-neighbourhood, repeated), in NumPy
on the read-back textures; raymarch rRMSE (corrected) per T. Usage: python lab/experiments/experiment_probe_dilation.py OUT.json [NAME=REFDIR ...]
(the H100 run is bench/h100-leaks/results.json: it made images worse, so nothing was built)."""
import json, sys
from dataclasses import replace
import numpy as np
from radiance_probes.gl.context import create_headless_context
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.bench.scenes import bench_scene
from radiance_probes.rendering.metrics import rrmse, corrected_rrmse
from radiance_probes.io.load import load_volume
from radiance_probes.twins.medium import sigma_t_at
from radiance_probes.viewer.probe_view import probe_centres

ctx = create_headless_context()
# NAME=DIR pairs: DIR holds an earlier bench run's refs/NAME.npy and results.json
refs = dict(a.split("=", 1) for a in sys.argv[2:]) or {"bonsai": ".refs/before", "foot": ".refs/foot"}
out = []

def dilate(data, thick, rounds=3):
    """data (nz, ny, nx, C); thick (nz, ny, nx) bool. Each round, a thick probe with thin
    neighbours takes their mean and becomes thin."""
    data = data.copy(); thick = thick.copy()
    nz, ny, nx = thick.shape
    for _ in range(rounds):
        valid = (~thick).astype(np.float64)
        acc = np.zeros_like(data); w = np.zeros(thick.shape)
        pv = np.pad(valid, 1); pd = np.pad(data * valid[..., None], ((1, 1), (1, 1), (1, 1), (0, 0)))
        for dz in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    if dz == dy == dx == 0:
                        continue
                    sl = (slice(1 + dz, 1 + dz + nz), slice(1 + dy, 1 + dy + ny), slice(1 + dx, 1 + dx + nx))
                    acc += pd[sl]; w += pv[sl]
        fill = thick & (w > 0)
        data[fill] = acc[fill] / w[fill][:, None]
        thick = thick & ~fill
    return data

for name, refdir in refs.items():
    scene = bench_scene(name, 512, 512)
    ref = np.load(f"{refdir}/refs/{name}.npy")
    noise = json.load(open(f"{refdir}/results.json"))["references"][name]["noise_rrmse"]
    vol = load_volume(scene.volume, scene.base_dir)
    for grid, walks in ((32, 256), (64, 512), (128, 256)):
        probes = replace(scene.probes, grid=(grid,) * 3, samples=walks)
        r = Renderer(ctx, scene.replace(probes=probes), vol)
        r.bake(seed=11)
        g = r.probe_grid
        n = g.grid
        original = [np.frombuffer(t.read(), np.float32 if g.precision == "rgba32f" else np.float16)
                    .reshape(n[2], n[1], n[0], 4).astype(np.float64) for t in g.textures]
        data = np.concatenate(original, axis=-1)
        centres = probe_centres(n, vol.half_extent, g.box).reshape(n[2], n[1], n[0], 3)
        res = r.resources
        s = r.scene
        sig = sigma_t_at(vol, res.table if hasattr(res, "table") else None, s.density_scale, centres)
        spacing = (np.asarray(g.box[1]) - np.asarray(g.box[0])) / np.asarray(n) if g.box else 2 * np.asarray(vol.half_extent) / np.asarray(n)
        tau_cell = sig * spacing.min()
        for T in (None, 16.0, 8.0, 4.0, 2.0, 1.0):
            d = data if T is None else dilate(data, tau_cell > T)
            for i, t in enumerate(g.textures):
                t.write(d[..., 4 * i:4 * i + 4].astype(np.float32 if g.precision == "rgba32f" else np.float16).tobytes())
            img = r.render("raymarch", spp=16, seed=3, samples_per_pass=16).image
            e = rrmse(img, ref)
            rec = dict(scene=name, grid=grid, walks=walks, T=T, thick=int((tau_cell > (T or 1e30)).sum()),
                       probes=int(tau_cell.size), rrmse=e, corrected=corrected_rrmse(e, noise))
            print(json.dumps(rec), flush=True)
            out.append(rec)
        r.release()
json.dump(out, open(sys.argv[1], "w"), indent=1)
