"""Empty-space skipping: the macrocell majorant grid (app/twins/majorant_grid.py, glsl/majorant_grid.comp) and
the DDA in delta and ratio tracking (glsl/lib/tracking.glsl).

The grid must bound sigma_t everywhere in every cell (NumPy twin and GPU-sampled sigma_t, sharp
volumes, a spiky transfer function), match its NumPy twin, and be rebuilt exactly when the
transfer function, density_scale or volume change. Tracking with it must stay unbiased and
resumable: transmittance estimates against quadrature, interrupted after every step or not, and a
path-traced image against the global-majorant version within noise."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from radiance_probes.twins.majorant_grid import (MAJORANT_SAFETY, density_range_grid,
                                                 macrocell_counts, majorant_grid, voxel_ranges)
from radiance_probes.twins.medium import density_at, sigma_t_at
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.resources import SceneResources
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.scene.transfer import transfer_table
from radiance_probes.io.volume import Volume
from radiance_probes.io.load import load_scene_volume
from glsl_harness import run_kernel

WHITE = {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]}
# Opacity 0 but for a spike one table row wide around 0.5 (256 rows: about 0.008 wide).
SPIKE = {"colormap": "viridis", "opacity": [[0.0, 0.0], [0.497, 0.0], [0.5, 1.0], [0.503, 0.0],
                                            [1.0, 0.0]]}
CAMERA = {"eye": [0.3, 0.4, 1.7], "target": [0, 0, 0], "fov_y": 35.0, "width": 8, "height": 8}


def _random_volume(dims=(37, 19, 9), seed=5, uint8=False) -> Volume:
    nx, ny, nz = dims
    r = np.random.default_rng(seed)
    data = r.uniform(size=(nz, ny, nx))
    data[r.uniform(size=data.shape) < 0.3] = 0.0          # scattered vacuum voxels
    data[:, :, : nx // 2] = 0.0                            # and a vacuum half
    if uint8:
        raw = np.round(data * 255).astype(np.uint8)
        return Volume((raw / 255.0).astype(np.float32), (1.0, 1.3, 0.7), "random_uint8",
                      (0.0, 255.0), "uint8", 0.0, 255.0)
    return Volume(data.astype(np.float32), (1.0, 1.3, 0.7), "random", (0.0, 1.0), "float32", 0.0, 1.0)


def _volume(name: str) -> Volume:
    if name == "random":
        return _random_volume()
    if name == "random-uint8":
        return _random_volume((21, 30, 17), seed=6, uint8=True)
    sizes = {"sheet": [40, 33, 24], "cloud": [64, 64, 64], "sphere": [30, 30, 30]}
    return load_scene_volume(parse_scene({"volume": {"builtin": name, "size": sizes[name]}}))


def _resources(ctx, volume: Volume, tf=SPIKE, density_scale=80.0, **kw) -> SceneResources:
    scene = parse_scene({"volume": {"builtin": "empty", "size": [2, 2, 2]}, "transfer_function": tf,
                         "density_scale": density_scale, "camera": CAMERA, **kw})
    return SceneResources(ctx, scene, volume)


def _cell_points(volume: Volume, per_cell: int, seed=0) -> tuple[np.ndarray, np.ndarray]:
    """Random points in every macrocell plus points on its faces and corners; (points, cell index
    [z, y, x] of each). Rounded to float32, as the GPU gets them."""
    cells = np.array(macrocell_counts(volume.dims))           # x, y, z
    he = volume.half_extent.astype(np.float64)
    size = 2 * he / cells
    r = np.random.default_rng(seed)
    idx = np.stack(np.meshgrid(*[np.arange(c) for c in cells], indexing="ij"), -1).reshape(-1, 3)
    frac = r.uniform(size=(len(idx), per_cell, 3))
    # a quarter of the points on a face, edge or corner of their cell
    snap = r.uniform(size=frac.shape) < 0.25
    frac = np.where(snap, np.round(frac), frac)
    pts = -he + (idx[:, None, :] + frac) * size
    pts = pts.reshape(-1, 3).astype(np.float32).astype(np.float64)
    cell_of = np.repeat(idx, per_cell, axis=0)
    return pts, cell_of[:, ::-1]   # [z, y, x]


# ---------------------------------------------------------------------------------------------
# the grid

def test_macrocell_counts():
    assert macrocell_counts((64, 64, 64)) == (8, 8, 8)
    assert macrocell_counts((1, 9, 1000)) == (1, 2, 64)
    assert macrocell_counts((256, 7, 512)) == (32, 1, 64)


@pytest.mark.parametrize("n,cells", [(1, 1), (7, 1), (8, 1), (9, 2), (64, 8), (100, 13), (1000, 64)])
def test_voxel_ranges_cover_the_trilinear_support(n, cells):
    lo, hi = voxel_ranges(n, cells)
    for i in range(cells):
        s = np.linspace(i * n / cells, (i + 1) * n / cells, 257) - 0.5   # voxel coordinates
        read_lo = np.clip(np.floor(s), 0, n - 1)
        read_hi = np.clip(np.floor(s) + 1, 0, n - 1)
        assert lo[i] <= read_lo.min() and read_hi.max() <= hi[i]
        assert hi[i] - lo[i] <= int(np.ceil(n / cells)) + 2   # and not much more


@pytest.mark.parametrize("name", ["sheet", "random", "random-uint8", "cloud"])
def test_density_ranges_bound_the_trilinear_density(name):
    volume = _volume(name)
    d_min, d_max = density_range_grid(volume.data)
    pts, cell = _cell_points(volume, 64)
    d = density_at(volume, pts)
    iz, iy, ix = cell.T
    assert np.all(d >= d_min[iz, iy, ix]) and np.all(d <= d_max[iz, iy, ix])
    assert d_min.dtype == d_max.dtype == np.float32


def test_sheet_cells_away_from_the_sheet_are_exactly_empty():
    volume = _volume("sheet")          # one voxel thick at y index 16 of 33
    d_min, d_max = density_range_grid(volume.data)
    table = transfer_table(parse_scene({"transfer_function": WHITE}).transfer_function)
    m = majorant_grid(d_min, d_max, table, 50.0)
    lo, hi = voxel_ranges(33, m.shape[1])
    touching = (lo <= 16) & (16 <= hi)
    assert touching.sum() in (1, 2)
    assert np.all(m[:, touching, :] > 0)
    np.testing.assert_array_equal(m[:, ~touching, :], 0.0)


@pytest.mark.parametrize("name", ["sheet", "random", "random-uint8", "cloud", "sphere"])
@pytest.mark.parametrize("tf", ["spike", "default", "white"])
def test_gpu_grid_matches_twin_and_bounds_sigma_t(ctx, name, tf):
    volume = _volume(name)
    spec = {"spike": SPIKE, "default": {}, "white": WHITE}[tf]
    scale = 80.0
    res = _resources(ctx, volume, spec, scale)
    try:
        grid = res.majorant_grid.read()
        table = res.table
        d_min, d_max = density_range_grid(volume.data)
        twin = majorant_grid(d_min, d_max, table, scale)
        assert grid.shape == twin.shape == macrocell_counts(volume.dims)[::-1]
        np.testing.assert_allclose(grid, twin, rtol=1e-5, atol=1e-4 * scale)
        np.testing.assert_array_equal(grid == 0, twin == 0)   # empty cells agree exactly
        assert res.majorant_grid.bound >= grid.max() * (1 - 1e-5)
        assert grid.max() <= res.majorant * MAJORANT_SAFETY * (1 + 1e-6)

        # sigma_t (NumPy twin, float64) at random points, faces and corners of every cell
        pts, cell = _cell_points(volume, 96, seed=len(name) * 7 + len(tf))
        iz, iy, ix = cell.T
        sigma = sigma_t_at(volume, table, scale, pts)
        assert np.all(sigma <= grid[iz, iy, ix]), (sigma - grid[iz, iy, ix]).max()

        # and sigma_t as the GPU samples it (texture filtering and the shader's lookup)
        res.bind()
        gpu_sigma = run_kernel(ctx, SIGMA_KERNEL, [pts.astype(np.float32).ravel()], (len(pts),),
                               uniforms=res.uniforms(), count=len(pts))
        assert np.all(gpu_sigma <= grid[iz, iy, ix]), (gpu_sigma - grid[iz, iy, ix]).max()
        if tf != "white":
            assert (grid == 0).any(), "the case should have empty cells to skip"
    finally:
        res.release()


SIGMA_KERNEL = """
#include "lib/medium.glsl"
layout(std430, binding = 0) readonly buffer In { float p[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    o[i] = sigma_t_at(vec3(p[3u * i], p[3u * i + 1u], p[3u * i + 2u]));
}
"""


def test_empty_volume_grid_is_all_zero(ctx):
    volume = _volume("sheet")
    volume = dataclasses.replace(volume, data=np.zeros_like(volume.data))
    res = _resources(ctx, volume, WHITE, 1e4)
    try:
        assert not res.majorant_grid.read().any()
        assert res.majorant_grid.bound == 0.0
        assert res.majorant > 0     # the global majorant still sees the table's opacity
    finally:
        res.release()


def test_grid_rebuilds_only_when_transfer_density_or_volume_change(ctx):
    base = {"volume": {"builtin": "cloud", "size": [24, 20, 16]}, "transfer_function": SPIKE,
            "density_scale": 30.0, "camera": CAMERA}
    res = SceneResources(ctx, parse_scene(base))
    try:
        g = res.majorant_grid
        first = g.read()
        assert g.builds == 1
        # camera, light, albedo, anisotropy: no rebuild
        for change in ({"camera": {**CAMERA, "eye": [1.0, 0.0, 1.0]}}, {"albedo": 0.5},
                       {"anisotropy": 0.3}, {"light": {"irradiance": [1, 2, 3]}}):
            res.update(parse_scene({**base, **change}))
            assert g.builds == 1, change
        # density_scale: rebuilt, scaled
        res.update(parse_scene({**base, "density_scale": 60.0}))
        assert g.builds == 2
        np.testing.assert_allclose(g.read(), 2 * first, rtol=1e-6)
        # transfer function: rebuilt, different, equal to the twin
        res.update(parse_scene({**base, "density_scale": 60.0, "transfer_function": WHITE}))
        assert g.builds == 3
        second = g.read()
        assert not np.allclose(second, 2 * first)
        d_min, d_max = density_range_grid(res.volume.data)
        np.testing.assert_allclose(second, majorant_grid(d_min, d_max, res.table, 60.0),
                                   rtol=1e-5, atol=1e-3)
        # a new volume: new ranges, rebuilt
        res.update(parse_scene({**base, "density_scale": 60.0, "transfer_function": WHITE,
                                "volume": {"builtin": "sheet", "size": [16, 16, 16]}}))
        assert g.builds == 4 and g.cells == (2, 2, 2)
        res.update(parse_scene({**base, "density_scale": 60.0, "transfer_function": WHITE,
                                "volume": {"builtin": "sheet", "size": [16, 16, 16]},
                                "camera": {**CAMERA, "fov_y": 20.0}}))
        assert g.builds == 4
    finally:
        res.release()


# ---------------------------------------------------------------------------------------------
# tracking with the grid: unbiased, resumable, robust

TRACK_KERNEL = """
#include "lib/rng.glsl"
#include "lib/medium.glsl"
#include "lib/tracking.glsl"
layout(std430, binding = 0) readonly buffer Rays { float rays[]; };   // origin, t_max, direction, t_min
layout(std430, binding = 1) writeonly buffer Out { vec4 o[]; };
uniform uint samples;
uniform int chunk;          // steps per call: the estimate is resumed after every `chunk` steps
uniform uint seed;
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    uint ray = i / samples;
    vec3 org = vec3(rays[8u * ray], rays[8u * ray + 1u], rays[8u * ray + 2u]);
    float t_max = rays[8u * ray + 3u];
    vec3 dir = vec3(rays[8u * ray + 4u], rays[8u * ray + 5u], rays[8u * ray + 6u]);
    float t_min = rays[8u * ray + 7u];
    // clipped to the box, as every caller does (the global majorant's loops assume it)
    float b0, b1;
    if (!box_intersect(org, dir, b0, b1))
        b0 = b1 = 0.0;
    t_min = max(t_min, b0);
    t_max = max(t_min, min(t_max, b1));
    uint rng = rng_seed(ray, i % samples, seed);
    uint rng_start = rng;
    // ratio tracking, continued from where each call stopped
    float t = t_min, transmittance = 1.0;
    int ratio_steps = 0;
    for (int k = 0; k < 4000; ++k) {
        int steps = chunk;
        bool done = ratio_track_continue(org, dir, t, t_max, transmittance, rng, steps);
        ratio_steps += chunk - steps;
        if (done)
            break;
        transmittance = k == 3999 ? -1.0 : transmittance;
    }
    bool ratio_used_rng = rng != rng_start;
    // delta tracking, restarted from where each call stopped (as the path tracer does)
    vec3 x = org;
    float t0 = t_min, t1 = t_max;
    int result = TRACK_OUT_OF_STEPS, delta_steps = 0;
    for (int k = 0; k < 4000 && result == TRACK_OUT_OF_STEPS; ++k) {
        int steps = chunk;
        float tc;
        result = delta_track(x, dir, t0, t1, rng, steps, tc);
        delta_steps += chunk - steps;
        if (result == TRACK_OUT_OF_STEPS) {
            x += tc * dir;
            t1 -= tc;
            t0 = max(t0 - tc, 0.0);
        }
    }
    float escaped = result == TRACK_ESCAPED ? 1.0 : (result == TRACK_COLLIDED ? 0.0 : -1.0);
    o[i] = vec4(transmittance, escaped, float(ratio_steps + (ratio_used_rng ? 1000000 : 0)),
                float(delta_steps));
}
"""


def _track(ctx, res: SceneResources, rays: np.ndarray, samples: int, chunk: int, grid: bool,
           seed=1) -> np.ndarray:
    res.use_majorant_grid = grid
    res.bind()
    out = run_kernel(ctx, TRACK_KERNEL, [rays.astype(np.float32).ravel()], (len(rays) * samples, 4),
                     uniforms={**res.uniforms(), "samples": samples, "chunk": chunk, "seed": seed},
                     count=len(rays) * samples)
    return out.reshape(len(rays), samples, 4)


def _quadrature_transmittance(volume, table, scale, rays, steps=3000) -> np.ndarray:
    org, t_max, d, t_min = rays[:, :3], rays[:, 3], rays[:, 4:7], rays[:, 7]
    he = volume.half_extent.astype(np.float64)
    out = []
    for o, tm, dd, t0 in zip(org, t_max, d, t_min):
        inv = 1.0 / np.where(dd == 0, 1e-30, dd)
        ta, tb = (-he - o) * inv, (he - o) * inv
        b0 = max(np.max(np.minimum(ta, tb)), 0.0, t0)
        b1 = min(np.min(np.maximum(ta, tb)), tm)
        if b1 <= b0:
            out.append(1.0)
            continue
        ts = b0 + (np.arange(steps) + 0.5) / steps * (b1 - b0)
        sig = sigma_t_at(volume, table, scale, o + ts[:, None] * dd)
        out.append(np.exp(-sig.sum() * (b1 - b0) / steps))
    return np.array(out)


def _rays(volume: Volume, n: int, seed=3) -> np.ndarray:
    """Rays from inside (some from cell faces, some along axes) and from outside the box."""
    r = np.random.default_rng(seed)
    he = volume.half_extent.astype(np.float64)
    cells = np.array(macrocell_counts(volume.dims))
    org = r.uniform(-1, 1, (n, 3)) * he
    d = r.normal(size=(n, 3))
    k = n // 4
    # origins exactly on macrocell faces (and box faces) along x and z
    face = -he + np.round((org + he) / (2 * he / cells)) * (2 * he / cells)
    org[:k, 0], org[:k, 2] = face[:k, 0], face[:k, 2]
    # directions along axes (two zero components) and in axis planes (one zero)
    axis = r.integers(0, 3, size=k)
    d[k:2 * k] = 0.0
    d[k + np.arange(k), axis] = r.choice([-1.0, 1.0], size=k)
    d[2 * k + np.arange(k), axis] = 0.0
    # from outside the box towards it
    org[3 * k:] = r.uniform(-1, 1, (n - 3 * k, 3)) * he * 3.0
    d[3 * k:] = -org[3 * k:] + r.uniform(-0.3, 0.3, (n - 3 * k, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t_max = np.full(n, 10.0)
    t_min = np.zeros(n)
    t_max[::7] = r.uniform(0.05, 0.6, size=len(t_max[::7]))   # segments ending inside
    t_min[1::9] = r.uniform(0.0, 0.3, size=len(t_min[1::9]))   # and starting inside
    t_min[2::11] = t_max[2::11] = 0.4                          # empty ranges
    rays = np.concatenate([org, t_max[:, None], d, t_min[:, None]], axis=1)
    return rays.astype(np.float32).astype(np.float64)


@pytest.mark.parametrize("case", ["cloud-white", "random-spike"])
def test_tracking_with_grid_is_unbiased_and_resumable(ctx, case):
    """Per ray: ratio-tracking transmittance and delta tracking's escape rate, with the grid and
    without, agree with quadrature within noise; and resumed after every step (or every 7), each
    sample is the very same as uninterrupted (same random numbers in the same order)."""
    if case == "cloud-white":
        volume = load_scene_volume(parse_scene({"volume": {"builtin": "cloud", "size": [24, 20, 16]}}))
        tf, scale = WHITE, 12.0
    else:
        volume = _random_volume((17, 12, 20), seed=9)
        tf, scale = {"colormap": "grey", "opacity": [[0.0, 0.0], [0.6, 0.0], [0.62, 1.0],
                                                     [0.64, 0.0], [1.0, 0.0]]}, 80.0
    res = _resources(ctx, volume, tf, scale)
    try:
        rays = _rays(volume, 48)
        ref = _quadrature_transmittance(volume, res.table, scale, rays)
        assert 0.01 < ref.min() and (ref < 0.8).sum() >= 8, "the rays should see real extinction"
        samples = 1024
        whole = {grid: _track(ctx, res, rays, samples, 1 << 20, grid, seed=11 + grid)
                 for grid in (True, False)}
        for grid, out in whole.items():
            assert (out[..., 0] >= 0).all() and (out[..., 1] >= 0).all(), "ran out of resumptions"
            for column in (0, 1):   # ratio transmittance, delta escape indicator
                est = out[..., column].mean(axis=1)
                # the sample's own spread, or where it saw nothing (all samples escaped), a
                # Bernoulli variable's at the reference transmittance
                se = np.maximum(out[..., column].std(axis=1), np.sqrt(ref * (1 - ref))) \
                    / np.sqrt(samples) + 1e-6
                z = (est - ref) / se
                assert np.abs(z).max() < 5.0, (grid, column, z)
                assert abs(z.mean()) < 3.0 / np.sqrt(len(z)) * 1.5, (grid, column, z.mean())
            for chunk in (1, 7):
                cut = _track(ctx, res, rays, samples, chunk, grid, seed=11 + grid)
                # ratio tracking resumes at the same t from the same origin: bit for bit, and
                # in as many steps
                np.testing.assert_array_equal(cut[..., 0], out[..., 0])
                np.testing.assert_array_equal(cut[..., 2], out[..., 2])
                # delta tracking restarts from the moved point, so positions round differently
                assert (cut[..., 1] == out[..., 1]).mean() > 0.999
                assert (cut[..., 3] == out[..., 3]).mean() > 0.99
        # empty ranges: transmittance 1; with the grid, no step and no random number
        empty = rays[:, 3] <= rays[:, 7]
        for grid, out in whole.items():
            assert (out[empty, :, 0] == 1.0).all() and (out[empty, :, 1] == 1.0).all()
            if grid:
                assert (out[empty, :, 2] == 0).all() and (out[empty, :, 3] == 0).all()
        if case == "random-spike":
            # a third of the macrocells lie in the vacuum half: fewer steps
            grid_steps, global_steps = whole[True][..., 3].mean(), whole[False][..., 3].mean()
            assert grid_steps < 0.8 * global_steps, (grid_steps, global_steps)
    finally:
        res.release()


def test_empty_cells_are_crossed_without_random_numbers(ctx):
    """Rays through the sheet volume parallel to the sheet and away from it only cross cells of
    majorant 0: transmittance exactly 1, escape always, no random number, one step per cell. In
    an all-vacuum volume tracking returns at once (no step)."""
    volume = _volume("sheet")
    res = _resources(ctx, volume, WHITE, 1e4)
    try:
        he = volume.half_extent.astype(np.float64)
        cells = macrocell_counts(volume.dims)
        ys = np.array([-0.9, -0.6, 0.6, 0.9]) * he[1]
        rays = []
        for y in ys:
            for d in ([1.0, 0, 0], [0, 0, -1.0], [0.6, 0, 0.8]):
                o = -np.array(d) * 2.0 + np.array([0.0, y, 0.0])
                rays.append([*o, 10.0, *d, 0.0])
        rays = np.array(rays)
        out = _track(ctx, res, rays, 8, 1 << 20, True)
        assert (out[..., 0] == 1.0).all() and (out[..., 1] == 1.0).all()
        assert (out[..., 2] < 1000000).all(), "a random number was drawn in empty cells"
        assert (out[..., 2] <= sum(cells)).all() and (out[..., 3] <= sum(cells)).all()
        # through the sheet, the same rays do see it
        through = np.array([[0.0, -2.0, 0.0, 10.0, 0.0, 1.0, 0.0, 0.0]])
        out = _track(ctx, res, through, 64, 1 << 20, True)
        assert out[..., 0].max() < 1e-3 and out[..., 1].max() == 0.0
    finally:
        res.release()
    res = _resources(ctx, dataclasses.replace(volume, data=np.zeros_like(volume.data), derived={}),
                     WHITE, 1e4)
    try:
        out = _track(ctx, res, rays, 8, 1 << 20, True)
        assert (out[..., 0] == 1.0).all() and (out[..., 1] == 1.0).all()
        assert (out[..., 2] == 0).all() and (out[..., 3] == 0).all()
        out = _track(ctx, res, rays, 8, 1 << 20, False)    # the global majorant walks the vacuum
        assert (out[..., 3] > 0).all()
    finally:
        res.release()


# ---------------------------------------------------------------------------------------------
# images

def test_image_with_grid_matches_global_majorant(ctx):
    """The default scene (cloud, sun, environment, 64 bounces) at 24 x 24: independent batches
    with and without the grid; per pixel and over the image the two agree within their noise."""
    scene = parse_scene({"camera": {"width": 24, "height": 24}})
    r = Renderer(ctx, scene)
    batches, spp = 8, 64
    images = {}
    try:
        for grid in (True, False):
            r.resources.use_majorant_grid = grid
            runs = []
            for b in range(batches):
                result = r.render("pt", spp=spp, seed=100 * b + int(grid), samples_per_pass=spp)
                assert result.stats["truncated_paths"] == 0
                assert result.stats["nonfinite_samples"] == 0
                runs.append(result.image.astype(np.float64))
            images[grid] = np.stack(runs)
    finally:
        r.release()
    a, b = images[True], images[False]
    var = a.var(0, ddof=1) / batches + b.var(0, ddof=1) / batches
    live = var > 1e-12               # pixels that see the cloud (the rest are the environment)
    assert live.mean() > 0.1
    np.testing.assert_array_equal(a.mean(0)[~live], b.mean(0)[~live])
    z = (a.mean(0) - b.mean(0))[live] / np.sqrt(var[live])
    # Welch's t with about 2 (batches - 1) = 14 degrees of freedom: E[z^2] = 14 / 12; path-traced
    # noise has heavier tails than a normal's, so the largest |z| gets room (measured over six
    # seed sets: E[z^2] 0.98 to 1.38, max |z| 3.0 to 6.8).
    assert np.mean(z ** 2) < 1.8, np.mean(z ** 2)
    assert abs(np.mean(z)) < 4.0 / np.sqrt(z.size) * 1.5, np.mean(z)
    assert np.abs(z).max() < 9.0
    # whole image: the mean radiance per channel
    whole_a, whole_b = a.mean(axis=(1, 2)), b.mean(axis=(1, 2))      # (batches, 3)
    se = np.sqrt(whole_a.var(0, ddof=1) / batches + whole_b.var(0, ddof=1) / batches)
    assert np.all(np.abs(whole_a.mean(0) - whole_b.mean(0)) < 4.5 * se)
    assert a.mean(0).max() > 0.05   # the scene is lit


def test_probe_bake_with_grid_matches_global_majorant(ctx):
    """The bake's walks use the same tracking: probe coefficients (every SH channel and the sun's
    transmittance) baked with and without the grid agree within the spread of independent bakes."""
    scene = parse_scene({"volume": {"builtin": "cloud", "size": [24, 20, 16]}, "density_scale": 40.0,
                         "camera": CAMERA, "probes": {"grid": [3, 3, 2], "samples": 128}})
    r = Renderer(ctx, scene)
    r.configure(walk_sun="ray")   # shadow rays from every walk event: the tracking this test is about
    bakes = 6
    coefficients = {}
    try:
        for grid in (True, False):
            r.resources.use_majorant_grid = grid
            runs = []
            for seed in range(bakes):
                probes = r.start_bake(seed=10 * seed + int(grid))
                while not probes.done:
                    probes.bake_pass(r.resources)
                runs.append(probes.coefficients().astype(np.float64).reshape(-1, 28))
            coefficients[grid] = np.stack(runs)
        assert r.resources.read_stats()["truncated_paths"] == 0
    finally:
        r.release()
    a, b = coefficients[True], coefficients[False]
    var = a.var(0, ddof=1) / bakes + b.var(0, ddof=1) / bakes
    live = var > 1e-12
    z = (a.mean(0) - b.mean(0))[live] / np.sqrt(var[live])
    assert live.sum() > 100
    assert np.mean(z ** 2) < 1.8, np.mean(z ** 2)
    assert np.abs(z).max() < 9.0


@pytest.mark.parametrize("density_scale", [100.0, 1e4])
def test_opaque_box_single_scattering_has_its_closed_form_with_and_without_the_grid(
        ctx, density_scale):
    """A homogeneous box, single scattering only, seen face on: near the middle of the face it is a
    semi-infinite medium, whose radiance albedo E p mu_s / (mu_s + mu_v) does not depend on
    sigma_t (mu_s, mu_v: the sun's and the view's cosines to the face's normal). Both tracking
    modes must give it at sigma_t = 100 and 1e4. The grid's walk used to end at its last face's
    snap distance and skip the sliver of medium there: +86% at sigma_t = 1e4."""
    from radiance_probes.rendering.settings import RenderSettings
    sun = np.array([0.3, 0.8, 0.52])
    sun /= np.linalg.norm(sun)
    scene = parse_scene({"volume": {"builtin": "constant", "size": [8, 8, 8]},
                         "transfer_function": WHITE, "density_scale": density_scale,
                         "albedo": 0.8, "max_bounces": 1,
                         "light": {"direction": sun.tolist(), "irradiance": [3, 3, 3]},
                         "environment": [0, 0, 0],
                         "camera": {"eye": [0, 0, 2.2], "target": [0, 0, 0], "fov_y": 10.0,
                                    "width": 8, "height": 8}})
    # the view's rays through the middle pixels are within 1 degree of the face's normal
    expected = 0.8 * 3.0 / (4 * np.pi) * sun[2] / (sun[2] + 1.0)
    means = []
    for skipping in (True, False):
        r = Renderer(ctx, scene, settings=RenderSettings(empty_space_skipping=skipping))
        try:
            image = r.render("pt", spp=256, seed=3, samples_per_pass=256).image
        finally:
            r.release()
        means.append(float(image[2:6, 2:6].mean()))
    np.testing.assert_allclose(means, expected, rtol=0.01)
