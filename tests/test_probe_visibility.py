"""Visibility-weighted probe interpolation (probes.interpolation "visibility",
glsl/lib/probe_visibility.glsl): the GLSL against its NumPy twin, the known answer it exists for (a
probe inside an opaque block no longer darkens the medium next to the block), and what it must
leave alone (a homogeneous medium: the trilinear images bit for bit; the furnace: exact)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from radiance_probes.gl.textures import TransferTable, volume_texture
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import parse_scene
from radiance_probes.twins.medium import sigma_t_at
from radiance_probes.twins.probe_visibility import blend, corner_weights
from radiance_probes.io.volume import Volume
from glsl_harness import PROBE_FETCH_KERNEL, run_kernel

WHITE_RAMP = {"rgba": [[1, 1, 1, 0.0], [1, 1, 1, 1.0]]}   # sigma_t = density_scale x density
FACE = 8          # the block fills voxels x < FACE of N along x
N = 24
THIN = 0.01       # the medium beside it: sigma_t 2 at density_scale 200 (the block's 200)


def block_volume(n: int = N, face: int = FACE, thin: float = THIN) -> Volume:
    """An opaque block x < face voxels, full height and depth, beside a thin homogeneous medium."""
    d = np.full((n, n, n), thin, np.float32)
    d[:, :, :face] = 1.0
    return Volume(d, (1.0, 1.0, 1.0), "block", (0.0, 1.0), "float32", 0.0, 1.0)


def _fetch(ctx, x, *, grid, values, volume, table, density_scale, visibility):
    """probe_fetch (grey, order 0: one texture, L00 in .r, the sun in .a) at points x over the
    box [-0.5, 0.5]^3, probes evenly spaced; returns (L00, sun) per point."""
    import moderngl
    probe_tex = ctx.texture3d(grid, 4, values.astype(np.float32).tobytes(), dtype="f4")
    probe_tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    probe_tex.repeat_x = probe_tex.repeat_y = probe_tex.repeat_z = False
    vt, tt = volume_texture(ctx, volume), TransferTable(ctx, table)
    try:
        probe_tex.use(2)
        vt.use(0)
        tt.use(1)
        out = run_kernel(
            ctx, PROBE_FETCH_KERNEL, [np.ascontiguousarray(x, np.float32).ravel()],
            (len(x), 3 * 9 + 1),
            defines={"PROBE_GREY": 1, "PROBE_SH_ORDER": 0, "PROBE_VISIBILITY": int(visibility),
                     "PROBE_VISIBILITY_MAX_CELL": 1.0},
            uniforms={"probe_textures": (2,), "probe_grid": grid,
                      "probe_box_min": (-0.5, -0.5, -0.5), "probe_box_size": (1.0, 1.0, 1.0),
                      "probe_radiance_scale": 1.0, "volume_density": 0, "transfer_function": 1,
                      "transfer_size": len(table), "density_scale": density_scale,
                      "majorant": density_scale * float(table[:, 3].max()),
                      "box_half_extent": tuple(float(v) for v in volume.half_extent)})
    finally:
        for obj in (probe_tex, vt, tt):
            obj.release()
    return out[:, 0], out[:, -1]


def test_visibility_weights_match_the_numpy_twin(ctx):
    """probe_fetch with PROBE_VISIBILITY 1 against app/twins/probe_visibility.py (weights from the
    twin's sigma_t, blend of the probes' texels) on random probe values around a dense block in a
    noisy medium; where the twin finds no probe occluded, GL's trilinear filter."""
    from radiance_probes.twins.medium import trilinear
    rng = np.random.default_rng(5)
    d = rng.uniform(0.0, 0.05, (N, N, N)).astype(np.float32)
    d[6:15, 4:12, 5:13] = 1.0
    volume = Volume(d, (1.0, 1.0, 1.0), "noisy block", (0.0, 1.0), "float32", 0.0, 1.0)
    table = np.array([[1, 1, 1, 0.0], [1, 1, 1, 1.0]], np.float32)
    scale = 40.0
    grid = (5, 4, 6)
    values = rng.uniform(0.1, 1.0, (grid[2], grid[1], grid[0], 4))
    x = rng.uniform(-0.55, 0.55, (3000, 3)).astype(np.float32).astype(np.float64)
    l00, sun = _fetch(ctx, x, grid=grid, values=values, volume=volume, table=table,
                      density_scale=scale, visibility=True)
    uvw = x + 0.5
    centres = lambda ijk: (ijk + 0.5) / np.asarray(grid) - 0.5
    ijk, weights, occluded = corner_weights(
        x, uvw, grid, (1.0, 1.0, 1.0), centres, lambda p: sigma_t_at(volume, table, scale, p),
        scale * float(table[:, 3].max()))
    for got, channel in ((l00, 0), (sun, 3)):
        twin = np.where(occluded, blend(values[..., channel], ijk, weights),
                        trilinear(values[..., channel], uvw * np.asarray(grid) - 0.5))
        err = np.abs(got - twin)
        # GL filters the density with 8-bit weights, so optical depths and the occluded test
        # differ a little near the block; the blend itself must agree
        assert np.median(err) < 1e-5, np.median(err)
        assert np.quantile(err, 0.98) < 0.02, np.quantile(err, 0.98)
    assert 0.1 < occluded.mean() < 0.9, occluded.mean()   # both paths were exercised
    # the trilinear build reads the same textures trilinearly everywhere
    l00_trilinear, _ = _fetch(ctx, x, grid=grid, values=values, volume=volume, table=table,
                              density_scale=scale, visibility=False)
    np.testing.assert_allclose(l00_trilinear, trilinear(values[..., 0], uvw * np.asarray(grid) - 0.5),
                               atol=2e-3)
    assert np.abs(l00_trilinear - l00)[occluded].max() > 0.05   # the weights did change something


def _block_renderer(ctx, interpolation: str, **kw) -> Renderer:
    scene = parse_scene({
        "volume": {"builtin": "constant", "size": [N, N, N]}, "transfer_function": WHITE_RAMP,
        "density_scale": 200.0, "albedo": 0.9, "environment": [0, 0, 0],
        "light": {"direction": [0, 1, 0], "irradiance": [3, 3, 3]},
        "camera": {"eye": [0.0, 0.0, 2.0], "target": [0, 0, 0], "width": 8, "height": 8},
        "probes": {"grid": [6, 6, 6], "samples": 8, "fit": "box", "interpolation": interpolation},
        **kw})
    return Renderer(ctx, scene, block_volume())


def test_a_probe_inside_an_opaque_block_no_longer_darkens_the_medium_beside_it(ctx):
    """Known answer: the sun straight above, an opaque block (sigma_t 200, 1/3 of the box along x,
    full height) beside a thin homogeneous medium (sigma_t 2). Nothing shadows the thin medium, so
    the sun's transmittance there is exp(-2 (0.5 - y)). The probes at x = -0.25 lie inside the
    block (transmittance 0); trilinear interpolation blends them into the thin medium up to the
    next probe plane (x = -0.083) and darkens it by up to 37%. Visibility weights leave them out:
    what the probes give there is the analytic transmittance up to interpolation in y."""
    r = _block_renderer(ctx, "visibility")
    try:
        r.bake(seed=3)
        g = r.probe_grid
        rng = np.random.default_rng(1)
        # in the thin medium, past the density's trilinear ramp at the face (x >= -0.146)
        x = np.column_stack([rng.uniform(-0.14, -0.09, 400), rng.uniform(-0.3, 0.3, 400),
                             rng.uniform(-0.3, 0.3, 400)])
        analytic = np.exp(-200.0 * THIN * (0.5 - x[:, 1]))
        values = np.concatenate([np.frombuffer(t.read(), np.float32).reshape(6, 6, 6, 4)
                                 for t in g.textures], -1)
        got = {}
        for visibility in (False, True):
            # the probes' own sun transmittance, read as the renderers read it
            sun_values = np.zeros((6, 6, 6, 4))
            sun_values[..., 3] = values[..., 3]
            _, got[visibility] = _fetch(
                ctx, x, grid=(6, 6, 6), values=sun_values, volume=r.resources.volume,
                table=r.resources.table, density_scale=200.0, visibility=visibility)
    finally:
        r.release()
    trilinear, visible = got[False] / analytic, got[True] / analytic
    print("sun transmittance / analytic: trilinear", trilinear.min(), trilinear.mean(),
          "visibility", visible.min(), visible.max())
    assert trilinear.min() < 0.7                       # the leak this exists for
    assert np.abs(visible - 1.0).max() < 0.03          # gone: within interpolation in y


def test_visibility_changes_nothing_in_a_homogeneous_medium(ctx):
    """No matter between a point and its probes beyond the point's own: every weight stays
    trilinear and the shader takes the hardware fetch, so the images are the same bit for bit."""
    images = {}
    for interpolation in ("trilinear", "visibility"):
        r = Renderer(ctx, parse_scene({
            "volume": {"builtin": "constant", "size": [10, 8, 9]}, "density_scale": 6.0,
            "camera": {"eye": [0.3, 0.2, 1.6], "target": [0, 0, 0], "width": 12, "height": 12},
            "probes": {"grid": [4, 3, 5], "samples": 16, "interpolation": interpolation}}))
        try:
            r.bake(seed=2)
            images[interpolation] = [r.render(m, spp=2, seed=4).image
                                     for m in ("raymarch", "probes-only")]
        finally:
            r.release()
    for a, b in zip(images["trilinear"], images["visibility"]):
        np.testing.assert_array_equal(a, b)
        assert a.max() > 0


@pytest.mark.parametrize("method", ["raymarch", "probes-only"])
def test_furnace_stays_exact_with_visibility_weights(ctx, method):
    """White furnace (albedo 1, constant environment) in a cloud of varying density: every probe
    holds the environment, and renormalised weights of equal values give that value."""
    env = [0.3, 0.6, 0.9]
    r = Renderer(ctx, parse_scene({
        "volume": {"builtin": "cloud", "size": [16, 12, 14]}, "transfer_function": WHITE_RAMP,
        "albedo": 1.0, "density_scale": 40.0, "environment": env, "max_bounces": 100000,
        "light": {"irradiance": [0, 0, 0]},
        "camera": {"eye": [0.0, 0.2, 1.3], "target": [0, 0, 0], "width": 16, "height": 16},
        "probes": {"grid": [4, 4, 4], "samples": 64, "interpolation": "visibility"}}))
    try:
        image = r.render(method, spp=4).image
    finally:
        r.release()
    np.testing.assert_allclose(image, np.broadcast_to(env, image.shape), rtol=1e-2)


def test_switching_the_interpolation_keeps_the_baked_probes(ctx):
    """The interpolation is read-side only (the viewer's Probes panel switches it live): the
    probes stay current, and the next image differs only where a probe is occluded."""
    r = _block_renderer(ctx, "trilinear")
    try:
        r.bake(seed=3)
        before = r.render("raymarch", spp=1, seed=1).image
        r.set_scene(r.scene.replace(probes=replace(r.scene.probes, interpolation="visibility")))
        assert r.probes_current()
        after = r.render("raymarch", spp=1, seed=1).image
        assert r.probes_current()
    finally:
        r.release()
    assert np.abs(after - before).max() > 0
