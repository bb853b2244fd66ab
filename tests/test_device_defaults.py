"""The viewer's per-device defaults: on a GPU the measured probe setting where the user named none;
a scene file's or the command line's setting is kept; llvmpipe keeps the scene's."""
from __future__ import annotations

import json

from radiance_probes.io.scene_file import parse_scene
from radiance_probes.rendering.budgets.device_defaults import (PROBES, RENDER_SCALE, probes_named,
                                                               with_device_probes)


def test_probes_named_by_option_scene_file_or_bundled_scene(tmp_path):
    named = tmp_path / "named.json"
    named.write_text(json.dumps({"probes": {"grid": 32}}))
    unnamed = tmp_path / "unnamed.json"
    unnamed.write_text(json.dumps({"probes": {"sh_window": "hann"}, "albedo": 0.5}))
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps({"albedo": 0.5}))
    assert probes_named(str(named), None, None)
    assert not probes_named(str(unnamed), None, None)
    assert not probes_named(str(bare), None, None)
    assert probes_named(str(bare), (8, 8, 8), None) and probes_named(None, None, 64)
    assert not probes_named(None, None, None)                       # the built-in scene
    assert not probes_named("foot.raw", None, None)                 # a volume file alone
    assert probes_named("foot.raw", None, None, bundled=named)      # its bundled scene names it
    assert not probes_named("foot.raw", None, None, bundled=bare)


def test_gpu_default_applies_only_where_nothing_was_named():
    scene = parse_scene({"probes": {"sh_window": "hann"}})
    grid, walks = PROBES["gpu"]
    on_gpu, said = with_device_probes(scene, "gpu", named=False)
    assert on_gpu.probes.grid == (grid,) * 3 and on_gpu.probes.samples == walks
    assert on_gpu.probes.sh_window == "hann"          # the rest of the probe settings kept
    assert said is not None and f"{grid}^3 x {walks}" in said and "--probe-grid" in said
    assert with_device_probes(scene, "gpu", named=True) == (scene, None)
    assert with_device_probes(scene, "software", named=False) == (scene, None)
    assert with_device_probes(on_gpu, "gpu", named=False) == (on_gpu, None)
    assert RENDER_SCALE["software"] < RENDER_SCALE["gpu"] == 1.0
