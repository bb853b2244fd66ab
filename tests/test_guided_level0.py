"""`guided`'s level 0 in bands (app/rendering/methods/guided_level0.py, Renderer._advance_level0):
a still image gets the whole frames it always got; the viewer's samples each pay about `ratio` of
a level-0 frame, never a whole one but the first; and a frame marched in bands gives every
pixel exactly what a whole frame gives it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from radiance_probes.io.scene_file import parse_scene
from radiance_probes.rendering.budgets.sample_bands import tile_grid
from radiance_probes.rendering.methods.guided_level0 import level0_groups_due
from radiance_probes.rendering.renderer import Renderer

SCENE = {"volume": {"builtin": "cloud", "size": [16, 14, 12]}, "density_scale": 30.0,
         "albedo": 0.9, "anisotropy": 0.3, "max_bounces": 6,
         "light": {"direction": [0.4, 0.8, -0.45], "irradiance": [3, 3, 3]},
         "environment": [0.1, 0.12, 0.15],
         "camera": {"eye": [0.2, 0.3, 1.6], "width": 40, "height": 24},
         "probes": {"grid": [4, 4, 4], "samples": 32}}


@pytest.mark.parametrize("ratio", [0.25, 0.5, 0.1, 1.0, 2.0])
def test_whole_frames_are_the_ceiling_of_samples_times_ratio(ratio):
    for s in range(1, 40):
        assert level0_groups_due(s, ratio, 15, bands=False) == math.ceil(s * ratio) * 15


@pytest.mark.parametrize("ratio", [0.25, 0.5, 0.1, 1.0])
def test_bands_never_fall_behind_and_each_sample_pays_its_share(ratio):
    groups = 60
    last = level0_groups_due(1, ratio, groups, bands=True)
    assert last == groups   # the first frame whole
    for s in range(2, 60):
        due = level0_groups_due(s, ratio, groups, bands=True)
        assert due >= level0_groups_due(s, ratio, groups, bands=False)   # never fewer frames
        # a sample's share of a frame (its groups rounded up), never a whole frame at once
        assert due - last <= math.ceil(ratio * groups) + 1
        if ratio < 1.0:
            assert due - last < groups
        last = due
    assert level0_groups_due(0, ratio, groups, bands=True) == 0


def test_level0_in_bands_is_what_whole_frames_give_each_pixel(ctx):
    """Five samples one at a time with level 0 in bands against five at once (whole frames):
    both hold two level-0 frames, and every pixel of level 0 is bit for bit the same; between
    them, the banded frame's groups advance by a sample's share."""
    r = Renderer(ctx, parse_scene(SCENE))
    try:
        r.bake(seed=3)
        r.begin("guided", seed=5)
        r.add_samples(5)
        whole = r._acc0.read()
        assert r._acc0.samples == 2 and r._acc0.groups_done == 0
        total = math.prod(tile_grid(r._acc0.width, r._acc0.height))
        r.begin("guided", seed=5)
        r.add_samples(1, level0_bands=True)
        assert (r._acc0.samples, r._acc0.groups_done) == (1, 0)
        seen = []
        for _ in range(4):
            r.add_samples(1, level0_bands=True)
            seen.append(r._acc0.samples * total + r._acc0.groups_done)
        assert seen == [level0_groups_due(s, 0.25, total, True) for s in range(2, 6)]
        assert r._acc0.samples == 2 and r._acc0.groups_done == 0
        np.testing.assert_array_equal(r._acc0.read(), whole)
        # in the middle of a frame the image is finite and its mean near the whole one's
        r.add_samples(1, level0_bands=True)
        assert 0 < r._acc0.groups_done < total
        assert np.all(np.isfinite(r.image()))
    finally:
        r.release()
