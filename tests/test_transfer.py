"""Transfer function tables (SPEC.md "Optical model")."""
import numpy as np
import pytest

from radiance_probes.io.scene_file import TransferFunctionSpec, parse_scene
from radiance_probes.scene.transfer import (ALIASES, COLORMAPS, colormap_rgb, lookup, opacity_curve,
                                            transfer_table)


@pytest.mark.parametrize("n", [2, 7, 256, 1000])
def test_table_shape_and_range(n):
    t = transfer_table(TransferFunctionSpec(resolution=n))
    assert t.shape == (n, 4) and t.dtype == np.float32
    assert np.isfinite(t).all() and t.min() >= 0.0 and t.max() <= 1.0


def test_opacity_through_control_points_and_constant_beyond():
    pts = ((0.25, 0.2), (0.5, 0.9), (0.75, 0.4))
    n = 101  # entries at multiples of 0.01, so every control point is an entry
    a = transfer_table(TransferFunctionSpec(opacity=pts, resolution=n))[:, 3]
    d = np.linspace(0, 1, n)
    for x, y in pts:
        assert a[round(x * (n - 1))] == pytest.approx(y, abs=1e-7)
    assert np.all(a[d <= 0.25] == np.float32(0.2))
    assert np.all(a[d >= 0.75] == np.float32(0.4))
    # linear in between
    np.testing.assert_allclose(a[35], 0.2 + 0.7 * 0.4, atol=1e-6)
    np.testing.assert_allclose(a[60], 0.9 - 0.5 * 0.4, atol=1e-6)


def test_default_opacity():
    a = transfer_table(TransferFunctionSpec(resolution=11))[:, 3]
    np.testing.assert_allclose(a, np.clip((np.linspace(0, 1, 11) - 0.2) / 0.8, 0, 1), atol=1e-6)


def test_single_control_point_is_constant():
    np.testing.assert_array_equal(opacity_curve(((0.3, 0.6),), 5), np.full(5, 0.6))


@pytest.mark.parametrize("name", COLORMAPS)
def test_every_colormap(name):
    spec = parse_scene({"transfer_function": {"colormap": name}}).transfer_function
    t = transfer_table(spec)
    assert t.shape == (256, 4)
    rgb = t[:, :3]
    assert rgb.min() >= 0 and rgb.max() <= 1
    assert np.ptp(rgb, axis=0).max() > 0.3  # not a constant colour
    if name in ALIASES:
        np.testing.assert_array_equal(rgb, colormap_rgb(ALIASES[name], 256).astype(np.float32))


def test_aliases_present():
    for alias in ("cool-warm", "gray", "rainbow"):
        assert alias in COLORMAPS
    assert np.allclose(colormap_rgb("gray", 5), np.linspace(0, 1, 5)[:, None].repeat(3, 1), atol=1e-3)


def test_alias_character():
    grey = colormap_rgb("gray", 9)
    np.testing.assert_array_equal(grey[:, 0], grey[:, 1])
    np.testing.assert_array_equal(grey[:, 1], grey[:, 2])
    cw = colormap_rgb("cool-warm", 9)
    assert cw[0, 2] > cw[0, 0] and cw[-1, 0] > cw[-1, 2]  # blue to red
    rb = colormap_rgb("rainbow", 9)
    assert rb[0, 2] > rb[0, 0] and rb[-1, 0] > rb[-1, 2]  # blue to red
    assert rb[4, 1] > 0.8 and rb[4, 1] > rb[4, 2]  # through green-yellow in the middle


def test_colormap_endpoints_are_the_preset_endpoints():
    from radiance_probes.scene.transfer import _colormap_tables
    for name, table in _colormap_tables().items():
        c = colormap_rgb(name, 17)
        np.testing.assert_allclose(c[0], table[0])
        np.testing.assert_allclose(c[-1], table[-1])


def test_explicit_rgba_rows_verbatim():
    rows = [[0.0, 0.1, 0.2, 0.0], [0.3, 0.4, 0.5, 0.25], [1.0, 0.9, 0.8, 1.0]]
    spec = parse_scene({"transfer_function": {"rgba": rows}}).transfer_function
    t = transfer_table(spec)
    assert t.shape == (3, 4)
    np.testing.assert_array_equal(t, np.asarray(rows, np.float32))


def test_lookup_interpolates_linearly():
    rng = np.random.default_rng(5)
    table = rng.uniform(size=(9, 4)).astype(np.float32)
    n = len(table)
    entries = np.linspace(0, 1, n)
    np.testing.assert_allclose(lookup(table, entries), table, atol=1e-7)
    mids = (entries[:-1] + entries[1:]) / 2
    np.testing.assert_allclose(lookup(table, mids), (table[:-1].astype(np.float64) + table[1:]) / 2,
                               atol=1e-7)
    quarter = entries[:-1] + 0.25 / (n - 1)
    np.testing.assert_allclose(lookup(table, quarter),
                               0.75 * table[:-1].astype(np.float64) + 0.25 * table[1:], atol=1e-7)
    # clamped outside [0, 1]
    np.testing.assert_allclose(lookup(table, np.array([-1.0, 2.0])), table[[0, -1]], atol=0)
    # shape (..., 4)
    assert lookup(table, np.zeros((2, 3))).shape == (2, 3, 4)


def test_lookup_equal_entries_exact():
    # An albedo of exactly 1 must stay exactly 1 (glsl/lib/medium.glsl writes a + (b - a) f).
    table = np.array([[1.0, 0.3, 0.7, 1.0]] * 5, np.float32)
    d = np.random.default_rng(0).uniform(size=10000)
    np.testing.assert_array_equal(lookup(table, d), np.broadcast_to(table[0].astype(np.float64), (10000, 4)))


def _mri_like_rows(n: int = 256) -> tuple:
    """An explicit RGBA table as an MRI scene gives it: transparent air, a ramp, a plateau."""
    d = np.linspace(0, 1, n)
    alpha = np.clip((d - 0.2) / 0.3, 0, 1) * 0.6
    return tuple((float(x), float(x) ** 2, 0.5, float(a)) for x, a in zip(d, alpha))


def test_the_editor_sees_an_explicit_tables_real_opacity():
    from radiance_probes.scene.transfer import opacity_points
    spec = TransferFunctionSpec(rgba=_mri_like_rows())
    points, error = opacity_points(spec)
    assert error < 1e-12 and len(points) <= 5          # the same curve, from its corners only
    table = transfer_table(spec)
    np.testing.assert_allclose(opacity_curve(points, len(table)), table[:, 3], atol=1e-6)
    assert points != ((0.0, 0.0), (1.0, 1.0))          # not the straight 0-to-1 ramp
    # an opacity curve is its own points
    curve = TransferFunctionSpec(opacity=((0.0, 0.0), (0.4, 0.1), (1.0, 0.7)))
    assert opacity_points(curve) == (curve.opacity, 0.0)


def test_a_noisy_table_is_shown_with_the_points_that_matter_and_says_how_far_off():
    from radiance_probes.scene.transfer import MAX_EDIT_POINTS, opacity_points
    rng = np.random.default_rng(3)
    d = np.linspace(0, 1, 4096)
    alpha = np.clip(np.sin(6 * d) * 0.5 + 0.5 + rng.normal(0, 0.002, d.size), 0, 1)
    spec = TransferFunctionSpec(rgba=tuple((0.1, 0.2, 0.3, float(a)) for a in alpha))
    points, error = opacity_points(spec)
    assert len(points) == MAX_EDIT_POINTS and points[0][0] == 0.0 and points[-1][0] == 1.0
    measured = np.abs(opacity_curve(points, d.size) - alpha).max()
    assert error == pytest.approx(measured) and 0 < error < 0.02


def test_editing_an_explicit_tables_curve_keeps_its_colours():
    from radiance_probes.scene.transfer import rgba_with_opacity
    rows = ((0.0, 0.0, 1.0, 0.0), (1.0, 0.5, 0.0, 0.5), (0.2, 1.0, 0.2, 1.0))
    spec = TransferFunctionSpec(rgba=rows)
    new = np.asarray(rgba_with_opacity(spec, ((0.0, 0.0), (0.25, 0.8), (1.0, 0.1))))
    assert len(new) >= spec.resolution and (len(new) - 1) % (len(rows) - 1) == 0
    step = (len(new) - 1) // (len(rows) - 1)
    np.testing.assert_array_equal(new[::step, :3], np.asarray(rows)[:, :3])  # old colours exact
    d = np.linspace(0, 1, len(new))
    np.testing.assert_allclose(new[:, 3], np.interp(d, [0, 0.25, 1], [0, 0.8, 0.1]), atol=1e-12)
    # colours in between are the old table's own interpolation
    old = np.stack([np.interp(d, [0, 0.5, 1], np.asarray(rows)[:, c]) for c in range(3)], 1)
    np.testing.assert_allclose(new[:, :3], old, atol=1e-12)
