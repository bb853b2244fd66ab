"""The raymarcher's opacity-gradient grid (app/rendering/grids/opacity_gradient_grid.py,
glsl/opacity_gradient_bake.comp, glsl/lib/opacity_gradient_grid.glsl): the baked grid against its
NumPy twin (app/twins/opacity_gradient_grid.py) with a crop, a clip plane and several channels;
its one-fetch read against the twin's trilinear lookup and, at the voxel centres, against the exact
gradient; the raymarcher's image with it close to the one with the exact gradient; baked only
where k > 0 and rebuilt only when the medium changes; the exact gradient where the volume is
bricked or the grid over its budget."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.rendering.grids import opacity_gradient_grid as grid_module
from radiance_probes.rendering.lab_options import LabOptions
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.rendering.settings import RenderSettings
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.twins import opacity_gradient_grid as og
from glsl_harness import run_kernel

TF = {"colormap": "grey", "opacity": [[0, 0], [0.3, 0.1], [0.6, 1], [1, 1]]}
CLIPS = {"none": {},
         "crop": {"crop": {"min": [-0.31, -0.27, -0.19], "max": [0.37, 0.29, 0.23]}},
         "clip plane": {"clip_plane": {"normal": [1, 0.5, 0.2], "distance": 0.05}}}


def _sphere(**kw):
    base = {"volume": {"builtin": "sphere", "size": [12, 10, 8]}, "transfer_function": TF,
            "surface": {"gradient_factor": 0.2}}
    base.update(kw)
    return parse_scene(base)


def _three_channels(tmp_path) -> dict:
    """Three channels [c, z, y, x] of 12 x 10 x 8 voxels, blobs in different places."""
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in (8, 10, 12)), indexing="ij")
    data = np.stack([np.clip(1.2 - 2.0 * np.sqrt((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2),
                             0, 1) for cx, cy, cz in ((-0.4, 0.0, 0.2), (0.4, -0.3, -0.2),
                                                      (0.1, 0.5, 0.0))]).astype(np.float32)
    path = tmp_path / "channels.npy"
    np.save(path, data)
    tf = [{"transfer_function": {"colors": [[0.0, 1, 0.3, 0.3]],
                                 "opacity": [[0, 0], [0.5, 0], [1, 1]]}},
          {"transfer_function": {"colors": [[0.0, 0.3, 1, 0.3]],
                                 "opacity": [[0, 0], [0.3, 0.0], [0.7, 0.6]]}, "enabled": False},
          {"transfer_function": {"colors": [[0.0, 0.3, 0.3, 1]],
                                 "opacity": [[0, 0.0], [0.4, 0], [1, 0.9]]}}]
    return {"volume": {"path": str(path), "axes": "czyx", "value_range": [0, 1]},
            "channels": tf}


@pytest.mark.parametrize("case", [*CLIPS, "channels"])
def test_the_baked_grid_is_the_twins_exact_gradient_at_the_voxel_centres(ctx, tmp_path, case):
    """The bake runs opacity_gradient itself at every voxel centre: the twin's central
    differences there, rounded to half floats (one half ulp either way: 2^-10 relative),
    whatever cuts or mixes the medium."""
    if case == "channels":
        scene = parse_scene({**_three_channels(tmp_path), "surface": {"gradient_factor": 0.2},
                             **CLIPS["crop"]})
    else:
        scene = _sphere(**CLIPS[case])
    r = Renderer(ctx, scene)
    try:
        r.bake_gradient_grid()
        grid = r.opacity_gradient_grid
        assert grid.usable and grid.builds == 1 and grid.gpu_bytes == 8 * 12 * 10 * 8
        gpu = grid.read().astype(np.float64)
        res = r.resources
        twin = og.opacity_gradient_bake(res.volume, res.medium_table, res.clip)
    finally:
        r.release()
    assert gpu.shape == (8, 10, 12, 3)
    scale = np.abs(twin).max()
    np.testing.assert_allclose(gpu, og.as_stored(twin), rtol=2e-3, atol=1e-5 * scale)
    assert scale > 1.0 and (np.abs(twin) < 1e-6).any()   # surfaces, and flat places


READ_KERNEL = """
#include "lib/medium.glsl"
#include "lib/phase.glsl"
#include "lib/hybrid_scattering.glsl"
#include "lib/opacity_gradient_grid.glsl"
layout(std430, binding = 0) readonly buffer In { float p[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 x = vec3(p[3u * i], p[3u * i + 1u], p[3u * i + 2u]);
    vec3 g = raymarch_opacity_gradient(x);
    vec3 e = opacity_gradient(x);
    o[6u * i] = g.x; o[6u * i + 1u] = g.y; o[6u * i + 2u] = g.z;
    o[6u * i + 3u] = e.x; o[6u * i + 4u] = e.y; o[6u * i + 5u] = e.z;
}
"""


def test_the_one_fetch_read_is_the_twins_trilinear_lookup(ctx):
    """raymarch_opacity_gradient with the grid: the twin's trilinear read of the texels, and at
    the voxel centres the exact gradient (to the half float's rounding); between them it departs
    from the exact gradient (the grid's bias, which the raymarcher's image test bounds)."""
    r = Renderer(ctx, _sphere(**CLIPS["crop"]))
    try:
        r.bake_gradient_grid()
        grid = r.opacity_gradient_grid
        res = r.resources
        he = res.volume.half_extent.astype(np.float64)
        rng = np.random.default_rng(4)
        between = rng.uniform(-1, 1, (500, 3)) * he
        centres = og.voxel_centres(res.volume.dims, he).reshape(-1, 3)
        pts = np.concatenate([between, centres]).astype(np.float32)
        res.bind()
        grid.bind()
        defines = {**res.defines(), "OPACITY_GRADIENT_GRID": 1}
        out = run_kernel(ctx, READ_KERNEL, [pts.ravel()], (len(pts), 6), count=len(pts),
                         uniforms={**res.uniforms(), **grid.uniforms()},
                         defines=defines).astype(np.float64)
        texels = grid.read().astype(np.float64)
    finally:
        r.release()
    read, exact = out[:, :3], out[:, 3:]
    scale = np.abs(texels).max()
    twin = og.opacity_gradient_grid(texels, he, pts.astype(np.float64))
    # llvmpipe filters in float (6e-7 of the largest texel apart here); a GPU's 8-bit filter
    # weights would be up to 1/512 of the neighbours' step off
    np.testing.assert_allclose(read, twin, atol=1e-3 * scale)
    n = len(between)
    np.testing.assert_allclose(read[n:], exact[n:], rtol=2e-3, atol=1e-5 * scale)
    assert np.abs(read[:n] - exact[:n]).max() > 1e-2 * scale   # not the exact gradient between


def test_for_an_opacity_linear_in_the_density_the_grid_is_the_exact_gradient_everywhere(ctx):
    """Where A is linear in the density, A is trilinear in space, and the central difference at x
    over one voxel is the trilinear blend of the differences at the voxel centres around x (along
    the axis: (1 - f) D(0) + f D(1), the other axes blend alike): the grid's read is the exact
    gradient at every point between the outermost centres, to half-float rounding. Its bias
    comes from the transfer function's curvature (and a crop's or clip plane's cut) alone."""
    r = Renderer(ctx, _sphere(transfer_function={"colormap": "grey",
                                                 "opacity": [[0, 0.1], [1, 0.7]]}))
    try:
        r.bake_gradient_grid()
        grid = r.opacity_gradient_grid
        res = r.resources
        he = res.volume.half_extent.astype(np.float64)
        hull = he * (1.0 - 1.0 / np.asarray(res.volume.dims))   # the voxel centres' box
        pts = (np.random.default_rng(6).uniform(-1, 1, (2000, 3)) * hull).astype(np.float32)
        res.bind()
        grid.bind()
        out = run_kernel(ctx, READ_KERNEL, [pts.ravel()], (len(pts), 6), count=len(pts),
                         uniforms={**res.uniforms(), **grid.uniforms()},
                         defines={**res.defines(), "OPACITY_GRADIENT_GRID": 1}).astype(np.float64)
    finally:
        r.release()
    read, exact = out[:, :3], out[:, 3:]
    scale = np.abs(exact).max()
    assert scale > 1.0
    np.testing.assert_allclose(read, exact, rtol=2e-3, atol=2e-3 * scale)


# The raymarcher's scene: a lit ball, probes, surfaces with a specular lobe.
LIT = {"density_scale": 30.0, "environment": [0.2, 0.3, 0.4],
       "light": {"direction": [0.4, 0.8, 0.45], "irradiance": [3, 3, 3]},
       "camera": {"eye": [0.3, 0.2, 1.6], "width": 24, "height": 24},
       "probes": {"grid": 4, "samples": 16}}


@pytest.mark.parametrize("k", [0.05, 0.5])
def test_the_raymarchers_image_with_the_grid_stays_close_to_the_exact_gradients(ctx, k):
    """The same probes and frames, the gradient read from the grid or computed exactly
    (LabOptions.opacity_gradient_grid False): measured on llvmpipe 1.1% relative RMS apart at
    k = 0.05 and 2.3% at k = 0.5, the mean within 0.3%; and the grid is read again bit for bit."""
    scene = _sphere(**LIT, surface={"gradient_factor": k, "roughness": 0.4,
                                    "specular": [0.04, 0.04, 0.04]})
    r = Renderer(ctx, scene)
    try:
        grid_image = r.render("raymarch", spp=8, seed=1).image
        assert r.opacity_gradient_grid.usable
        r.lab = LabOptions(opacity_gradient_grid=False)
        exact_image = r.render("raymarch", spp=8, seed=1).image
        r.lab = LabOptions()
        again = r.render("raymarch", spp=8, seed=1).image
        builds = r.opacity_gradient_grid.builds
    finally:
        r.release()
    assert again.tobytes() == grid_image.tobytes() and builds == 1
    rel = np.sqrt(np.mean((grid_image - exact_image) ** 2) / np.mean(exact_image ** 2))
    assert 1e-4 < rel < 0.04, rel   # it is another gradient, and a close one
    np.testing.assert_allclose(grid_image.mean(), exact_image.mean(), rtol=0.01)


def test_baked_where_k_is_above_zero_and_again_only_when_the_medium_changes(ctx):
    scene = _sphere(**LIT, surface={"gradient_factor": 0.0})
    r = Renderer(ctx, scene)
    try:
        r.render("raymarch", spp=1)
        assert r.opacity_gradient_grid is None   # k = 0: nothing made, nothing read
        r.set_scene(scene.replace(surface=type(scene.surface)(gradient_factor=0.3)))
        r.render("raymarch", spp=1)
        grid = r.opacity_gradient_grid
        assert grid.usable and grid.builds == 1
        for change in ({"camera": {**LIT["camera"], "eye": [0.5, 0.1, 1.5]}},   # not the medium
                       {"density_scale": 60.0},   # A = sigma_t / density_scale does not move
                       {"surface": {"gradient_factor": 0.6}}):
            r.set_scene(_sphere(**{**LIT, "surface": {"gradient_factor": 0.3}, **change}))
            r.render("raymarch", spp=1)
            assert grid.builds == 1, change
        for n, change in enumerate(({"transfer_function": {"colormap": "grey",
                                                           "opacity": [[0, 0], [1, 1]]}},
                                    CLIPS["crop"], CLIPS["clip plane"]), start=2):
            r.set_scene(_sphere(**{**LIT, "surface": {"gradient_factor": 0.3}, **change}))
            r.render("raymarch", spp=1)
            assert grid.builds == n, change
        r.render("pt", spp=1)   # the path tracer keeps the exact gradient: no bake for it
        assert grid.builds == 4
        r.set_scene(_sphere(**LIT, surface={"gradient_factor": 0.0}))
        r.render("raymarch", spp=1)   # surfaces off: the grid's memory given back
        assert grid.texture is None and grid.gpu_bytes == 0
    finally:
        r.release()


@pytest.mark.parametrize("method", ["raymarch", "refine"])
def test_an_images_bake_time_holds_the_grids_bake(ctx, method, monkeypatch):
    """A record's total is everything its image cost: render()'s bake_ms holds the grid's bake
    wherever the image's raymarcher needed one (refine's too), and the grid is baked once."""
    r = Renderer(ctx, _sphere(**LIT, surface={"gradient_factor": 0.3}))
    grid_ms = []
    real = r.bake_gradient_grid

    def bake():
        grid_ms.append(real())
        return grid_ms[-1]
    monkeypatch.setattr(r, "bake_gradient_grid", bake)
    # the probes' and the light grid's bakes run, their times taken as 0: what is left is the grid's
    for name in ("bake", "bake_light"):
        work = getattr(r, name)
        monkeypatch.setattr(r, name, lambda *a, _work=work, **kw: _work(*a, **kw) and 0.0)
    try:
        result = r.render(method, spp=8, seed=1)
        assert r.opacity_gradient_grid.builds == 1
    finally:
        r.release()
    assert grid_ms and grid_ms[0] > 0.0 and all(ms == 0.0 for ms in grid_ms[1:])
    assert result.bake_ms == grid_ms[0]


def test_the_exact_gradient_where_the_volume_is_bricked_or_the_grid_over_budget(ctx, monkeypatch):
    scene = _sphere(**LIT, volume={"builtin": "sphere", "size": [16, 16, 16]},
                    surface={"gradient_factor": 0.3})
    r = Renderer(ctx, scene, settings=RenderSettings(brick_size=8))
    try:
        assert r.resources.bricked
        r.render("raymarch", spp=1)
        grid = r.opacity_gradient_grid
        assert not grid.usable and "bricked" in grid.refusal and grid.texture is None
    finally:
        r.release()
    monkeypatch.setattr(grid_module, "MAX_BYTES", 8 * 16 ** 3 - 1)
    r = Renderer(ctx, scene)
    try:
        r.render("raymarch", spp=1)
        grid = r.opacity_gradient_grid
        assert not grid.usable and "budget" in grid.refusal and grid.builds == 0
        over = r.render("raymarch", spp=2, seed=5).image
        r.lab = LabOptions(opacity_gradient_grid=False)
        exact = r.render("raymarch", spp=2, seed=5).image
    finally:
        r.release()
    assert over.tobytes() == exact.tobytes()   # the exact gradient's image, bit for bit
