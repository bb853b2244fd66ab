"""The render methods' registry (app/methods.py): one list every front end reads, and every method
it and the README name renders through the Python API (small sizes, llvmpipe)."""
from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

import radiance_probes as rp
from radiance_probes.methods import (ACCUMULATED, METHODS, MOVIE_METHODS, NAMES, PROBE_LIT,
                                     REFERENCE, VIEWER_METHODS, method)

ROOT = Path(__file__).resolve().parents[1]
SMALL = dict(width=12, height=10, probes={"grid": 2, "samples": 8})


def readme_methods() -> list[str]:
    """The methods the README's "Which method when" table names, in its order."""
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Which method when"):]
    section = section[:section.index("\n## ", 1)]
    return re.findall(r"^\| `([a-z-]+)` \|", section, re.M)


def test_the_readme_names_exactly_the_registered_methods():
    named = readme_methods()
    assert len(named) >= 5
    assert sorted(named) == sorted(NAMES)


@pytest.mark.parametrize("name", sorted(set(NAMES) | set(readme_methods())))
def test_every_method_renders_through_the_api(name):
    image = rp.render(method=name, spp=2, seed=1, **SMALL)
    a = np.asarray(image)
    assert a.shape == (10, 12, 3) and np.isfinite(a).all()
    assert image.method == name and image.spp == 2
    assert float(np.abs(a - a[0, 0]).max()) > 1e-3   # the volume shows


def test_the_front_ends_read_the_registry():
    from radiance_probes.api import render as _api
    from radiance_probes.rendering.renderer import METHODS as ACCUMULATED_BY_RENDERER
    from radiance_probes.io.scene_schema import scene_schema
    from radiance_probes.viewer.input import SHORTCUTS
    assert rp.METHODS == NAMES and set(rp.DEFAULT_SPP) == set(NAMES)
    assert _api.METHODS is NAMES and ACCUMULATED_BY_RENDERER == ACCUMULATED
    viewer = scene_schema()["properties"]["viewer"]
    viewer = next(v for v in (viewer, *viewer.get("anyOf", ()), *viewer.get("oneOf", ()))
                  if "properties" in v)
    assert viewer["properties"]["method"]["enum"] == list(VIEWER_METHODS)
    keys = {s.keys: s for s in SHORTCUTS}
    for m in METHODS.values():
        if m.viewer_key is not None:
            assert m.name in keys[m.viewer_key].what
    from radiance_probes.cli.main import build_parser
    parser = build_parser()
    render = parser._subparsers._group_actions[0].choices["render"]
    choices = next(a.choices for a in render._actions if a.dest == "method")
    assert tuple(choices) == NAMES


def test_each_record_is_consistent():
    from radiance_probes.rendering.settings import RenderSettings
    settings = {f.name for f in dataclasses.fields(RenderSettings)}
    assert REFERENCE in NAMES and not METHODS[REFERENCE].needs_probes
    assert set(MOVIE_METHODS) <= set(ACCUMULATED) and set(VIEWER_METHODS) <= set(NAMES)
    assert len({m.viewer_key for m in METHODS.values() if m.viewer_key}) == len(VIEWER_METHODS)
    for m in METHODS.values():
        assert m.doc and "\n" not in m.doc
        assert m.default_spp >= 1
        assert set(m.options) <= settings, f"{m.name}: options not in RenderSettings"
        assert set(m.parts) <= set(ACCUMULATED)
        if m.probe_lighting:
            assert m.needs_probes and m.path_states and m.name in PROBE_LIT
    with pytest.raises(ValueError, match="known: pt"):
        method("nope")


def test_a_composite_method_has_no_single_accumulation(ctx):
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.io.scene_file import default_scene
    r = Renderer(ctx, default_scene())
    try:
        for m in METHODS.values():
            if m.composite:
                with pytest.raises(ValueError, match="render"):
                    r.begin(m.name, 8, 8)
    finally:
        r.release()
