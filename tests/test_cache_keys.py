"""Cache keys derived from the frozen records (app/rendering/cache_keys.py): every field of the Scene
and of RenderSettings is in exactly one group, and changing any field changes exactly the keys
whose groups hold it (a new field without a group, or without a variant here, fails)."""
from __future__ import annotations

import dataclasses
from dataclasses import replace

import pytest

from radiance_probes.rendering import cache_keys as ck
from radiance_probes.rendering.settings import RenderSettings
from radiance_probes.io.scene_file import default_scene
from radiance_probes.scene.types import (AreaLightSpec, BookmarkSpec, ChannelSpec, ClipPlaneSpec,
                                         CropSpec, EnvironmentMapSpec, Scene, ViewerSpec)

SPLIT = ("probes", "light")   # the records whose fields the groups name one by one

BASE = default_scene()
LIGHT = AreaLightSpec("sphere", (0.0, 2.0, 0.0), 0.2)
# A changed value for every field of the Scene (dotted: a field of a split record).
SCENE_VARIANTS = {
    "volume": replace(BASE.volume, size=(32, 32, 32)),
    "transfer_function": replace(BASE.transfer_function, colormap="viridis"),
    "density_scale": 50.0,
    "albedo": 0.5,
    "anisotropy": 0.4,
    "light.direction": (0.0, 1.0, 0.0),
    "light.irradiance": (1.0, 2.0, 3.0),
    "environment": (0.2, 0.2, 0.2),
    "environment_map": EnvironmentMapSpec("sky.exr"),
    "max_bounces": 8,
    "camera": replace(BASE.camera, eye=(1.0, 0.5, 2.0)),
    "probes.grid": (8, 8, 8),
    "probes.samples": 64,
    "probes.sh_window": "hann",
    "probes.precision": "rgba16f",
    "probes.sh_order": 2,
    "probes.fit": "box",
    "probes.channels": 3,
    "probes.layout": "adaptive",
    "probes.adaptive_strength": 0.8,
    "probes.adaptive_indicator": "sun",
    "probes.interpolation": "visibility",
    "surface": replace(BASE.surface, gradient_factor=1.0),
    "area_lights": (LIGHT,),
    "crop": CropSpec((-0.2, -0.2, -0.2), (0.2, 0.2, 0.2)),
    "clip_plane": ClipPlaneSpec((0.0, 1.0, 0.0), 0.1),
    "bookmarks": (BookmarkSpec("a", (0.0, 0.0, 3.0)),),
    "viewer": ViewerSpec(method="raymarch"),
    "channels": (ChannelSpec(BASE.transfer_function),),
    "time": 1,
    "base_dir": "/elsewhere",
}
# A changed value for every field of RenderSettings.
SETTINGS_VARIANTS = {
    "walk_sun": "ray", "walk_sun_correction": 0.1, "walk_adaptive": 0.0, "sun_lobe": False,
    "gather_event": 2, "bake_warm": False, "light_max_side": 256, "light_min_side": 32,
    "light_follows_probes": True, "light_precision": "f4", "light_segment_target": 1024,
    "raymarch_stage": "fragment", "raymarch_step": 0.25, "empty_space_skipping": False,
    "guided_level0_ratio": 0.5, "guided_direction_control": False,
    "volume_memory_bytes": 1 << 20, "brick_size": 16, "shadow_tracking": "residual",
    "bake_level": 1,
}
SETTINGS = RenderSettings().resolved(software=True)


def _scene_with(path: str, value) -> Scene:
    if "." in path:
        record, name = path.split(".")
        return BASE.replace(**{record: replace(getattr(BASE, record), **{name: value})})
    return BASE.replace(**{path: value})


def _keys(scene, settings) -> dict:
    return {"majorant_grid": ck.majorant_grid_key(scene),
            "visible_region": ck.visible_region_key(scene),
            "light_grid": ck.light_grid_key(scene, settings),
            "opacity_gradient_grid": ck.opacity_gradient_grid_key(scene),
            "area_light_grid": ck.area_light_grid_key(scene),
            "probe_bake": ck.probe_bake_key(scene, settings)}


def _group_of(groups: dict, path: str) -> str:
    (group,) = [g for g, paths in groups.items() if path in paths]
    return group


def test_every_field_is_in_exactly_one_group():
    paths = ck.field_paths(Scene, SPLIT)
    grouped = [p for g in ck.SCENE_GROUPS.values() for p in g]
    assert sorted(grouped) == sorted(paths), "Scene fields and SCENE_GROUPS differ"
    names = [f.name for f in dataclasses.fields(RenderSettings)]
    grouped = [n for g in ck.SETTINGS_GROUPS.values() for n in g]
    assert sorted(grouped) == sorted(names), "RenderSettings fields and SETTINGS_GROUPS differ"
    assert set(SCENE_VARIANTS) == set(paths) and set(SETTINGS_VARIANTS) == set(names)


@pytest.mark.parametrize("path", sorted(SCENE_VARIANTS))
def test_a_scene_field_changes_exactly_the_keys_of_its_group(path):
    before = _keys(BASE, SETTINGS)
    after = _keys(_scene_with(path, SCENE_VARIANTS[path]), SETTINGS)
    group = _group_of(ck.SCENE_GROUPS, path)
    for name, (groups, _) in ck.KEYS.items():
        changed = before[name] != after[name]
        if name == "visible_region" and path == "density_scale":
            assert not changed   # only whether it is positive
            assert ck.visible_region_key(BASE.replace(density_scale=0.0)) != before[name]
            continue
        if name == "opacity_gradient_grid" and path == "density_scale":
            assert not changed   # the opacity A = sigma_t / density_scale does not depend on it
            continue
        assert changed == (group in groups), (name, path, group)


@pytest.mark.parametrize("name", sorted(SETTINGS_VARIANTS))
def test_a_setting_changes_exactly_the_keys_of_its_group(name):
    before = _keys(BASE, SETTINGS)
    after = _keys(BASE, replace(SETTINGS, **{name: SETTINGS_VARIANTS[name]}))
    group = _group_of(ck.SETTINGS_GROUPS, name)
    for key, (_, groups) in ck.KEYS.items():
        assert (before[key] != after[key]) == (group in groups), (key, name, group)


def test_the_bake_reads_the_light_grid_settings_only_where_its_walks_read_the_grid():
    ray = replace(SETTINGS, walk_sun="ray")
    assert ck.probe_bake_key(BASE, ray) == ck.probe_bake_key(
        BASE, replace(ray, light_max_side=128))
    assert ck.probe_bake_key(BASE, replace(ray, shadow_tracking="residual")) != ck.probe_bake_key(
        BASE, replace(ray, shadow_tracking="residual", light_max_side=128))


def test_a_disabled_area_light_bakes_nothing_new():
    off = replace(LIGHT, enabled=False)
    assert ck.probe_bake_key(BASE.replace(area_lights=(off,)), SETTINGS) == ck.probe_bake_key(
        BASE, SETTINGS)


def test_adaptive_planes_key_follows_the_sun_only_for_the_sun_indicator():
    sun = BASE.replace(probes=replace(BASE.probes, adaptive_indicator="sun"))
    moved = lambda s: s.replace(light=replace(s.light, direction=(0.0, 1.0, 0.0)))   # noqa: E731
    assert ck.adaptive_planes_key(BASE, SETTINGS) == ck.adaptive_planes_key(moved(BASE), SETTINGS)
    assert ck.adaptive_planes_key(sun, SETTINGS) != ck.adaptive_planes_key(moved(sun), SETTINGS)
    assert ck.adaptive_planes_key(BASE, SETTINGS) != ck.adaptive_planes_key(
        BASE.replace(density_scale=50.0), SETTINGS)
