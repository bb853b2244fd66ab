"""The budgeted bake (issue 12): slices of chunks give the same probes as whole passes; a warm
restart after an edit ends at the cold bake's probes; an edit in the middle of a bake restarts it
for the new state, and the old state's partial probes never count as finished."""
from __future__ import annotations

import numpy as np
import pytest

from app.render.renderer import Renderer
from app.scene import parse_scene

SCENE = {"volume": {"builtin": "cloud", "size": [8, 8, 8]}, "density_scale": 30.0,
         "albedo": 0.8, "camera": {"width": 24, "height": 16},
         "probes": {"grid": [4, 4, 4], "samples": 192, "fit": "box"}}


def _textures(r) -> list[np.ndarray]:
    return [np.frombuffer(t.read(), np.float32).copy() for t in r.probe_grid.textures]


@pytest.fixture
def renderer(ctx):
    r = Renderer(ctx, parse_scene(SCENE))
    yield r
    r.release()


def _small_chunks(r, probes=5):
    """Many chunks per pass (the grid's buffers are sized for more, so fewer is safe)."""
    r.start_bake(0)
    r.probe_grid.chunk_probes = probes


def test_slices_give_the_probes_of_one_whole_bake(renderer):
    r = renderer
    _small_chunks(r)
    grid = r.probe_grid
    assert grid.chunks_per_pass == 13 and grid.passes_total == 3
    r.invalidate()
    r.bake(seed=5)
    whole = _textures(r)
    r.invalidate()
    slices = 0
    while not r.probes_current():
        ms = r.bake_step(5, budget_ms=1e-6)      # one chunk a slice
        assert ms > 0
        slices += 1
        if slices == 1:
            assert grid.next_chunk == 1 and not grid.done
    assert slices == grid.chunks_per_pass * grid.passes_total
    assert all(np.array_equal(a, b) for a, b in zip(whole, _textures(r)))
    assert np.abs(whole[0]).max() > 0


def test_budget_follows_the_measured_chunk_time(renderer):
    r = renderer
    _small_chunks(r)
    r.invalidate()
    r.bake_step(1, budget_ms=1e-6)
    per_chunk = next(iter(r._chunk_ms.values()))
    before = r.probe_grid.chunks_left
    r.bake_step(1, budget_ms=per_chunk * 4.5)   # about 4 chunks fit
    ran = before - r.probe_grid.chunks_left
    assert 2 <= ran <= 8


def test_warm_restart_ends_at_the_cold_bake(renderer):
    r = renderer
    r.bake(seed=2)
    old = _textures(r)
    edited = r.scene.replace(density_scale=36.0)
    r.set_scene(edited)
    r.bake_warm = False
    r.bake(seed=9)
    cold = _textures(r)
    r.set_scene(r.scene.replace(density_scale=30.0))
    r.bake(seed=2)
    assert all(np.array_equal(a, b) for a, b in zip(old, _textures(r)))
    r.set_scene(edited)
    r.bake_warm = True
    r.bake_step(9)          # the first pass: blended with the old probes
    first = _textures(r)
    assert r.probe_grid.warm_walks > 0
    while not r.probes_current():
        r.bake_step(9)
    warm = _textures(r)
    assert all(np.array_equal(a, b) for a, b in zip(cold, warm))
    # while it ran, the shown probes lay between the old ones and the new mean
    assert not np.array_equal(first[0], cold[0]) and not np.array_equal(first[0], old[0])


def test_an_edit_in_the_middle_of_a_bake_is_not_lost(renderer):
    r = renderer
    _small_chunks(r)
    r.invalidate()
    r.bake_step(4, budget_ms=1e-6)
    r.bake_step(4, budget_ms=1e-6)
    assert not r.probes_current()
    edited = r.scene.replace(albedo=0.5)
    r.set_scene(edited)
    assert not r.probes_current()       # the old state's partial probes are not final
    while not r.probes_current():
        r.bake_step(4, budget_ms=1e-6)
    assert r._baked_key == r.bake_key()
    got = _textures(r)
    r.bake_warm = False
    r.invalidate()
    r.bake(seed=4)
    assert all(np.array_equal(a, b) for a, b in zip(got, _textures(r)))
