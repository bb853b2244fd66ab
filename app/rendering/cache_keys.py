"""What each cached GPU product depends on, read from the frozen records (Scene, RenderSettings)
rather than written out field by field.

Every field of the Scene belongs to exactly one group of SCENE_GROUPS (the probes' and the sun's
records are split across groups, field by field: "probes.sh_window"), and every field of
RenderSettings to one of SETTINGS_GROUPS; tests/test_cache_keys.py holds that for every field, and
that changing any field changes exactly the keys whose groups hold it. A cached thing's key is the
values of the groups it depends on (KEYS), plus what the renderer derives (the volume's version,
the crop resolved against it, the resolved SH order, ...). So a new field joins every key of its
group, and a field in no group fails the test: none is forgotten silently, as `density_scale` once
had to be copied into each key by hand.
"""
from __future__ import annotations

import dataclasses

# The Scene's fields by what they act on.
SCENE_GROUPS: dict[str, tuple[str, ...]] = {
    # sigma_t everywhere: the majorant grid, the light grid, the visible region, the probes
    "medium": ("volume", "time", "transfer_function", "channels", "density_scale", "crop",
               "clip_plane"),
    # the sun's direction: the light grid marches along it
    "sun": ("light.direction",),
    # the light arriving (not the medium's optical depth): the probes hold it
    "light": ("light.irradiance", "environment", "environment_map"),
    # the area lights: the probes hold their light, and their optical-depth grid marches towards
    # them
    "area_lights": ("area_lights",),
    # how light scatters in the medium: the probes hold it
    "transport": ("albedo", "anisotropy", "max_bounces", "surface"),
    # the probe grid and what its bake stores
    "probe_bake": ("probes.grid", "probes.samples", "probes.precision", "probes.sh_order",
                   "probes.fit", "probes.channels", "probes.layout", "probes.adaptive_strength",
                   "probes.adaptive_indicator"),
    # how the probes are read at render time (never a re-bake)
    "probe_read": ("probes.sh_window", "probes.interpolation"),
    # the camera and what the viewer keeps; the folder relative paths are read from (what it
    # loads is the volume's version and the environment's map): no cached product
    "view": ("camera", "bookmarks", "viewer", "base_dir"),
}

# RenderSettings' fields by what they act on.
SETTINGS_GROUPS: dict[str, tuple[str, ...]] = {
    # what the probes' bake stores
    "bake": ("walk_sun", "walk_sun_correction", "walk_adaptive", "sun_lobe", "shadow_tracking",
             "empty_space_skipping"),
    # what the bake reads once the renderer has resolved it: its keys hold the resolved value
    # (Renderer.bake_level: -1, the level the probes' spacing allows, is that level)
    "bake_resolved": ("bake_level",),
    # the light grid's texels (what it stores)
    "light_grid": ("light_max_side", "light_min_side", "light_follows_probes", "light_precision"),
    # how work is cut or restarted, the results the same (up to float rounding): no key
    "schedule": ("light_segment_target", "bake_warm"),
    # read at render time (never a re-bake)
    "read": ("gather_event", "raymarch_stage", "raymarch_step", "guided_level0_ratio",
             "guided_direction_control"),
    # where the volume is placed (one texture or bricks): a new placement is a new volume version
    "placement": ("volume_memory_bytes", "brick_size"),
}

# Fields whose value enters a key through a function: a disabled area light lights nothing.
_NORMALISE = {
    "area_lights": lambda lights: tuple(light for light in lights if light.enabled),
}

# Each cached product: the Scene groups and the RenderSettings groups its key reads (beyond what
# the renderer derives: the probe bake's key also holds the resolved SH order and bake level).
# The probe bake's light_grid group counts where the walks read the grid.
KEYS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "majorant_grid": (("medium",), ()),
    "visible_region": (("medium",), ()),
    "light_grid": (("medium", "sun"), ("light_grid",)),
    "opacity_gradient_grid": (("medium",), ()),
    "area_light_grid": (("medium", "area_lights"), ()),
    "probe_bake": (("medium", "sun", "light", "area_lights", "transport", "probe_bake"),
                   ("bake", "light_grid")),
}


def _value(record, path: str):
    value = record
    for name in path.split("."):
        value = getattr(value, name)
    normalise = _NORMALISE.get(path)
    return normalise(value) if normalise is not None else value


def scene_key(scene, *groups: str, exclude: tuple[str, ...] = ()) -> tuple:
    """The values of the Scene fields in `groups` (in the groups' order), but `exclude`."""
    return tuple(_value(scene, path) for g in groups for path in SCENE_GROUPS[g]
                 if path not in exclude)


def settings_key(settings, *groups: str) -> tuple:
    """The values of the RenderSettings fields in `groups`."""
    return tuple(getattr(settings, name) for g in groups for name in SETTINGS_GROUPS[g])


def majorant_grid_key(scene) -> tuple:
    """The majorant grid's (and the BakeMedium's): the medium."""
    return scene_key(scene, *KEYS["majorant_grid"][0])


def visible_region_key(scene) -> tuple:
    """Where the transfer function makes the medium visible: the medium, of whose density scale
    only whether it is positive (glsl/visible_region.comp)."""
    return (*scene_key(scene, *KEYS["visible_region"][0], exclude=("density_scale",)),
            scene.density_scale > 0)


def opacity_gradient_grid_key(scene) -> tuple:
    """The raymarcher's opacity-gradient grid (opacity_gradient_grid.py): the medium but its
    density scale, which the opacity A = sigma_t / density_scale does not depend on."""
    return scene_key(scene, *KEYS["opacity_gradient_grid"][0], exclude=("density_scale",))


def light_grid_key(scene, settings) -> tuple:
    """The sun's light grid: the medium, the sun's direction, the grid's texels."""
    groups, setting_groups = KEYS["light_grid"]
    return (*scene_key(scene, *groups), *settings_key(settings, *setting_groups))


def area_light_grid_key(scene) -> tuple:
    """The area lights' optical-depth grid (area_light_grid.py): the medium and the enabled
    lights (their strength and colour too: a slider's change re-bakes a grid it need not, one
    march a texel)."""
    return scene_key(scene, *KEYS["area_light_grid"][0])


def walks_read_light_grid(settings) -> bool:
    """Whether the bake's walks read the light grid (their sun, or their shadow rays' control)."""
    return settings.walk_sun == "grid" or settings.shadow_tracking == "residual"


def probe_bake_key(scene, settings) -> tuple:
    """The probes' bake: everything but the view and the read side."""
    groups, (bake, light_grid) = KEYS["probe_bake"]
    return (*scene_key(scene, *groups), *settings_key(settings, bake),
            settings_key(settings, light_grid) if walks_read_light_grid(settings) else None)


def adaptive_planes_key(scene, settings) -> tuple:
    """An adaptive layout's planes (beside the grid and box they are for): the medium, the
    layout's strength and indicator, and for the "sun" indicator the light grid's key."""
    sun = scene.probes.adaptive_indicator == "sun"
    return (*scene_key(scene, "medium"), scene.probes.adaptive_strength,
            scene.probes.adaptive_indicator, light_grid_key(scene, settings) if sun else None)


def field_paths(record_type, split: tuple[str, ...] = ()) -> list[str]:
    """Every field of a record type as a group names it: a field named in `split` by its own
    record's fields ("probes.grid"), others whole."""
    hints = {f.name: f for f in dataclasses.fields(record_type)}
    paths = []
    for name in hints:
        if name in split:
            sub = _record_type_of(record_type, name)
            paths.extend(f"{name}.{f.name}" for f in dataclasses.fields(sub))
        else:
            paths.append(name)
    return paths


def _record_type_of(record_type, name: str):
    default = record_type()
    return type(getattr(default, name))
