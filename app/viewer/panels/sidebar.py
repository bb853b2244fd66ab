"""The sidebar: ImGui sections for render, data, transfer function, light, probes, stats, camera
and files, and help."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from imgui_bundle import ImVec2, imgui, implot

from radiance_probes.rendering.renderer import MAX_GATHER_EVENT, RAYMARCH_STAGES
from radiance_probes.frontend import controls as C
from radiance_probes.methods import METHODS as REGISTRY, REFERENCE, VIEWER_METHODS as METHODS
from radiance_probes.io.scene_file import (ORIENTATIONS, PROBE_FITS, PROBE_INDICATORS,
                                           PROBE_INTERPOLATIONS, PROBE_LAYOUTS, PROBE_PRECISIONS,
                                           SH_ORDERS, SH_WINDOWS)
from radiance_probes.io.builtin_volumes import BUILTIN_VOLUMES
from radiance_probes.viewer.layout import SIDEBAR_WIDTH
from radiance_probes.viewer.overlays import shortcut_table
from radiance_probes.viewer.state import (DISPLAY_MODES, PROBE_VIEWS, angles_from_direction,
                                          colour_and_strength, scaled)
from radiance_probes.viewer.panels.crop_panel import crop_section
from radiance_probes.viewer.panels.movie_panel import movie_section
from radiance_probes.viewer.panels.time_panel import time_section
from radiance_probes.viewer.panels.tf_editor import data_ticks, heat_legend, transfer_panel



def sidebar(v) -> None:
    s = v.ui_scale
    height = imgui.get_io().display_size.y
    imgui.set_next_window_pos(ImVec2(0, 0))
    imgui.set_next_window_size(ImVec2(SIDEBAR_WIDTH * s, height))
    flags = (imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_collapse
             | imgui.WindowFlags_.no_title_bar)
    imgui.begin("Radiance probes", None, flags)
    imgui.push_text_wrap_pos(0.0)     # every text and hint wraps at the panel's edge, never cut
    imgui.push_item_width(-150 * s)
    for title, draw in SECTIONS:
        if title == "Time" and v.time_steps <= 1:   # only for a volume with a time axis
            continue
        imgui.set_next_item_open(title not in CLOSED_AT_START, imgui.Cond_.once)
        if imgui.collapsing_header(title):
            v.widgets.note(title)
            draw(v)
        else:
            v.widgets.note(title)
    imgui.pop_item_width()
    if v.state.messages:
        imgui.separator()
        imgui.text_wrapped(v.state.messages[-1])
    imgui.pop_text_wrap_pos()
    imgui.end()


def radio_width(choice: str, style) -> float:
    """A radio button's width: its circle (the frame height), the gap and its label."""
    return (imgui.get_frame_height() + style.item_inner_spacing.x
            + imgui.calc_text_size(choice).x)


def _radio_row(v, label: str, choices, current: str, prefix: str = "") -> str | None:
    imgui.text(label)
    chosen = None
    style = imgui.get_style()
    right = imgui.get_cursor_screen_pos().x + imgui.get_content_region_avail().x
    for i, choice in enumerate(choices):
        if i and (imgui.get_item_rect_max().x + style.item_spacing.x
                  + radio_width(choice, style) <= right):
            imgui.same_line()           # on this line where it fits whole, else on the next
        if imgui.radio_button(f"{choice}##{label}", current == choice):
            chosen = choice
        v.widgets.note(f"{prefix}{choice}")
    return chosen


def render_section(v) -> None:
    state, ui, s = v.state, v.widgets, v.ui_scale
    chosen = _radio_row(v, "Method", METHODS, state.method)
    if chosen:
        state.set_method(chosen)
    chosen = _radio_row(v, "View", DISPLAY_MODES, state.display, "view ")
    if chosen:
        state.set_display(chosen)
    if state.display == "split":
        changed, i = imgui.combo("Right half", METHODS.index(state.split_method), list(METHODS))
        ui.note("Right half")
        if changed:
            state.split_method = METHODS[i]
        changed, value = imgui.slider_float("Divider", state.split_position, 0.0, 1.0, "%.2f")
        if changed:
            state.split_position = value
    if state.display == "error":
        _error_summary(v)
        changed, value = imgui.slider_float("Heat max", state.heat_max, 0.01, 10.0, "%.2f",
                                            imgui.SliderFlags_.logarithmic)
        if changed:
            state.heat_max = value
        heat_legend(imgui.get_content_region_avail().x, 10 * s, state.heat_max)
    chosen = _radio_row(v, "Probe grid", PROBE_VIEWS, state.probe_view, "probes ")
    if chosen:
        state.probe_view = chosen
    if state.probe_view != "off":
        from radiance_probes.viewer.probe_view import PROBE_SLAB_AXES
        chosen = _radio_row(v, "Probe slab", PROBE_SLAB_AXES, state.probe_slab_axis, "slab ")
        if chosen:
            state.probe_slab_axis = chosen
        slab = v.probe_slab()
        if slab is not None:
            changed, value = imgui.slider_float("Slab position", state.probe_slab, 0.0, 1.0,
                                                f"plane {slab[1]}")
            ui.note("Slab position")
            if changed:
                state.probe_slab = float(value)
    drawn = v.probes_drawn()
    if drawn is not None:
        stride = f", every {drawn['stride']}th per axis" if drawn["stride"] > 1 else ""
        where = (f"of {drawn['visible']} in visible medium" if drawn["visible"]
                 else "(none in visible medium)")
        imgui.text_disabled(f"{len(drawn['indices'])} of {drawn['total']} probes drawn, "
                            f"{where}{stride}; colour: radiance at the exposure below")
    dn = v.session.denoise
    changed, value = imgui.checkbox("Denoise", dn.enabled)
    ui.note("Denoise")
    if changed:
        dn.set_enabled(value)
    if dn.note:
        imgui.text_wrapped(dn.note)
    elif dn.enabled and dn.runs:
        imgui.text_disabled(f"filtered {dn.runs} images; last frame's filtering "
                            f"{dn.last_ms:.1f} ms (wall)")
    changed, value = imgui.checkbox("Volume box", state.show_box)
    ui.note("Volume box")
    if changed:
        state.show_box = value
    changed, value = imgui.slider_float(C.EXPOSURE.label, state.exposure, C.EXPOSURE.lo, C.EXPOSURE.hi, "%.2f",
                                        imgui.SliderFlags_.logarithmic)
    ui.note("Exposure")
    if changed:
        state.exposure = value
    changed, value = imgui.slider_int(C.MAX_SAMPLES.label, state.max_samples, C.MAX_SAMPLES.lo, C.MAX_SAMPLES.hi, "%d",
                                      imgui.SliderFlags_.logarithmic)
    if changed:
        state.max_samples = max(1, value)
    changed, value = imgui.slider_float(C.RENDER_SCALE.label, state.render_scale, C.RENDER_SCALE.lo,
                                        C.RENDER_SCALE.hi, "%.3f")
    if changed:
        state.render_scale = value
    r = v.session.renderer
    changed, i = imgui.combo("Raymarch stage", RAYMARCH_STAGES.index(r.raymarch_stage), list(RAYMARCH_STAGES))
    if changed:
        r.configure(raymarch_stage=RAYMARCH_STAGES[i])
        v.session.restart(["raymarch"])
    if "probes" in state.shown_methods():
        changed, value = imgui.slider_int("Gather at event", r.probe_gather_event, 1,
                                          MAX_GATHER_EVENT)
        ui.note("Gather at event")
        if changed:   # read-side only: the probes stay
            r.configure(gather_event=min(max(int(value), 1), MAX_GATHER_EVENT))
            v.session.restart(["probes"])
        if r.probe_gather_event > 1:
            imgui.text_disabled(f"probes: events 1-{r.probe_gather_event - 1} path traced, "
                                f"probes read at event {r.probe_gather_event}")
            most = r.gather_bounces_past_limit()
            if most is not None:
                bounces = r.scene.max_bounces
                imgui.text_wrapped(f"max_bounces is {bounces}: paths may scatter up to {most} "
                                   f"times (the probes hold {bounces - 1} events whatever the "
                                   f"gather)")
    changed, value = imgui.checkbox("Empty-space skipping", r.resources.use_majorant_grid)
    ui.note("Empty-space skipping")
    if changed:   # the same images either way (unbiased); the probes re-bake by their key
        r.configure(empty_space_skipping=bool(value))
        v.session.restart()
    for method in state.shown_methods():
        n = v.session.samples(method)
        imgui.progress_bar(min(n / state.max_samples, 1.0), ImVec2(-1, 0),
                           f"{method}: {n} / {state.max_samples} samples")


def _error_summary(v) -> None:
    state = v.state
    if state.method == REFERENCE:
        imgui.text_wrapped("The error view compares a probe method with the path tracer: choose one.")
        return
    rmse = v.error_meter.value
    text = "n/a" if not np.isfinite(rmse) else f"{rmse:.4f}"
    imgui.text(f"relative RMSE {state.method} vs pt: {text}")
    n, n_pt = v.error_meter.samples
    imgui.text_disabled(f"measured at {n} spp against pt at {n_pt} spp (its own noise is "
                        "included; measured again each time both double)")


def data_section(v) -> None:
    state, ui = v.state, v.widgets
    vol = v.session.volume
    if state.scene_path:
        imgui.text_wrapped(f"scene {state.scene_path}")
    imgui.text(f"{vol.name}")
    imgui.text(f"dims {vol.dims[0]} x {vol.dims[1]} x {vol.dims[2]}   {vol.raw_dtype}")
    sp = vol.spacing
    imgui.text(f"spacing {sp[0]:g}, {sp[1]:g}, {sp[2]:g}")
    # the values as loaded (level 0 of a store shown at a coarser level): a store whose range
    # pass was not needed has them once read
    extents = (v.session.renderer.resources.given_volume or vol).raw_extents()
    values = (f"values {extents[0][0]:g} .. {extents[0][1]:g}" if extents else
              "values: not read (the scene's range maps them)")
    imgui.text(f"{values}; 0..1 = {vol.value_range[0]:g} .. {vol.value_range[1]:g}")
    xs, heights = v.histogram()
    if implot.begin_plot("##histogram", ImVec2(-1, 90 * v.ui_scale),
                         implot.Flags_.no_title | implot.Flags_.no_legend | implot.Flags_.no_menus
                         | implot.Flags_.no_box_select | implot.Flags_.no_mouse_text
                         | implot.Flags_.no_inputs):
        implot.setup_axes("", "", implot.AxisFlags_.no_label,
                          implot.AxisFlags_.no_label | implot.AxisFlags_.no_tick_labels)
        implot.setup_axes_limits(0.0, 1.0, 0.0, 1.05, implot.Cond_.always)
        ticks, labels = data_ticks(vol.value_range)
        implot.setup_axis_ticks(implot.ImAxis_.x1, ticks, labels)
        implot.plot_bars("histogram", xs, heights, 1.0 / len(xs))
        implot.end_plot()
    imgui.text_disabled("histogram in data units over the value range or window (log counts)")
    if state.scene.volume.path is not None:
        chosen = _radio_row(v, "Orientation", ORIENTATIONS, state.scene.volume.orientation,
                            prefix="orientation ")
        if chosen and chosen != state.scene.volume.orientation:
            state.set_volume(orientation=chosen)
        imgui.text_disabled("patient: +x left, +y superior, +z anterior, where the file says")
    if v.loading is not None:   # a file opened, read on a thread
        imgui.text_wrapped(v.loading.progress())
    if v.opening is not None:
        imgui.text_wrapped(v.opening.progress())
    stream = v.session.renderer.resources.stream
    if stream is not None and stream.status() is not None:
        imgui.text_wrapped(stream.status())
    for note in vol.notes:
        if vol.dicom_listing is None or "DICOM series" not in note:   # the list below says it
            imgui.text_wrapped(note)
    series_list(v, vol)
    if imgui.button("Open file..."):
        v.files.open_dialog()
    ui.note("Open file...")
    imgui.same_line()
    if imgui.button("Open folder..."):   # a TIFF stack or a DICOM series
        v.files.open_folder_dialog()
    ui.note("Open folder...")
    imgui.same_line()
    imgui.text_disabled("or drop one on the window")
    names = list(BUILTIN_VOLUMES)
    for i, name in enumerate(names):
        if i % 3:
            imgui.same_line()
        if imgui.button(f"{name}##builtin"):
            v.open_builtin(name)
        ui.note(f"builtin {name}")
    for path in v.dataset_paths:
        clicked, _ = imgui.selectable(f"{path.name}##dataset", False)
        ui.note(f"dataset {path.name}")
        if clicked:
            v.open_path(str(path))


def series_list(v, vol) -> None:
    """A DICOM folder's series to pick from: the one shown selected, those that make no volume
    greyed out with the reason."""
    listing = vol.dicom_listing
    if listing is None or len(listing.series) < 2:
        return
    imgui.text(f"{len(listing.series)} DICOM series in {listing.where.name}:")
    for s in listing.series:
        current = vol.dicom_series is not None and s.uid == vol.dicom_series.uid
        flags = imgui.SelectableFlags_.disabled if s.problem else 0
        clicked, _ = imgui.selectable(f"{s.label(reason=False)}##series{s.number}", current, flags)
        v.widgets.note(f"series {s.number}")
        if s.problem and imgui.is_item_hovered(imgui.HoveredFlags_.allow_when_disabled):
            imgui.set_tooltip(s.problem)
        if clicked and not current:
            v.state.set_volume(series=s.uid)


def light_section(v) -> None:
    state, ui = v.state, v.widgets
    light = state.scene.light
    az, el = angles_from_direction(light.direction)
    changed_az, az = imgui.slider_float(C.SUN_AZIMUTH.label, az, C.SUN_AZIMUTH.lo, C.SUN_AZIMUTH.hi, "%.0f deg")
    ui.note("Sun azimuth")
    changed_el, el = imgui.slider_float(C.SUN_ELEVATION.label, el, C.SUN_ELEVATION.lo, C.SUN_ELEVATION.hi, "%.0f deg")
    ui.note("Sun elevation")
    if changed_az or changed_el:
        state.set_light_angles(az, el)
    d = state.scene.light.direction
    imgui.text_disabled(f"towards the sun: ({d[0]:.2f}, {d[1]:.2f}, {d[2]:.2f})")
    _colour_strength(v, "Sun", state.scene.light.irradiance, C.SUN_STRENGTH.hi,
                     lambda rgb: state.edit(light=replace(state.scene.light, irradiance=rgb)))
    area_light_section(v)
    environment_section(v)


def area_light_section(v) -> None:
    """The scene's area lights (docs/scene-format.md): each switched on or off, moved, resized,
    its strength set; a sphere light added above the volume. A light that would reach into the
    volume box is not moved there (the error panel says why)."""
    from radiance_probes.scene.area_lights import check_area_lights
    from radiance_probes.scene.types import MAX_AREA_LIGHTS, AreaLightSpec, SceneError
    state, ui = v.state, v.widgets
    lights = list(state.scene.area_lights)

    def apply(index: int, light) -> None:
        edited = tuple(light if i == index else l for i, l in enumerate(lights)) \
            if index < len(lights) else (*lights, light)
        try:
            check_area_lights(state.scene.replace(area_lights=edited), v.session.volume.half_extent)
        except SceneError as exc:
            state.error(str(exc))
            return
        state.edit(area_lights=edited)

    for i, light in enumerate(lights):
        label = f"{light.shape} light {i + 1}"
        changed, on = imgui.checkbox(f"{label}##on{i}", light.enabled)
        ui.note(f"{label} on")
        if changed:
            apply(i, replace(light, enabled=bool(on)))
        changed, pos = imgui.drag_float3(f"Position##light{i}", list(light.position), 0.01)
        ui.note(f"{label} position")
        if changed:
            apply(i, replace(light, position=tuple(float(c) for c in pos)))
        if light.shape == "sphere":
            changed, size = imgui.slider_float(f"Radius##light{i}", float(light.size), 0.01, 2.0)
            if changed:
                apply(i, replace(light, size=float(size)))
        changed, strength = imgui.slider_float(f"Strength##light{i}", float(light.strength), 0.0,
                                               1000.0, "%.2f", imgui.SliderFlags_.logarithmic)
        ui.note(f"{label} strength")
        if changed:
            apply(i, replace(light, strength=float(strength)))
    if len(lights) < MAX_AREA_LIGHTS and imgui.button("Add a sphere light"):
        sun = np.asarray(state.scene.light.direction, np.float64)
        apply(len(lights), AreaLightSpec(shape="sphere", position=tuple(float(c) for c in 1.2 * sun),
                                         size=0.15, strength=20.0))
    ui.note("Add a sphere light")


def environment_section(v) -> None:
    """A constant colour, or a map (README: environment maps) with its scale and rotation."""
    state, ui = v.state, v.widgets
    env = state.scene.environment_map
    if env is None:
        _colour_strength(v, "Environment", state.scene.environment, C.ENVIRONMENT_STRENGTH.hi,
                         lambda rgb: state.edit(environment=rgb))
    else:
        imgui.text(f"Environment map: {Path(env.path).name}")
        changed, scale = imgui.slider_float("Environment scale", env.scale, 0.0, 100.0, "%.3f",
                                            imgui.SliderFlags_.logarithmic)
        ui.note("Environment scale")
        if changed:
            state.set_environment_map(scale=max(float(scale), 0.0))
        changed, rotation = imgui.slider_float("Environment rotation", env.rotation, -180.0, 180.0,
                                               "%.0f deg")
        ui.note("Environment rotation")
        if changed:
            state.set_environment_map(rotation=rotation)
        if imgui.button("Constant environment"):
            state.set_environment_map("")
        ui.note("Constant environment")
    changed, text = imgui.input_text("Map file (.exr, .hdr, .npy)", v.environment_map_text)
    ui.note("Map file")
    if changed:
        v.environment_map_text = text
    imgui.same_line()
    if imgui.button("Load map") and v.environment_map_text.strip():
        p = Path(v.environment_map_text.strip()).expanduser()
        state.set_environment_map(str(p.resolve()) if p.is_file() else str(p))
    ui.note("Load map")


def _colour_strength(v, name: str, rgb, max_strength: float, apply) -> None:
    key = f"{name} colour"
    colour, strength = colour_and_strength(rgb)
    colour = v.remembered_colours.get(key, colour) if strength == 0.0 else colour
    changed_c, new_colour = imgui.color_edit3(f"{name} colour", list(colour), imgui.ColorEditFlags_.float)
    changed_s, new_strength = imgui.slider_float(f"{name} strength", strength, 0.0, max_strength, "%.2f",
                                                 imgui.SliderFlags_.logarithmic)
    v.widgets.note(f"{name} strength")
    if changed_c or changed_s:
        v.remembered_colours[key] = tuple(new_colour)
        apply(scaled(new_colour, new_strength))


def probes_section(v) -> None:
    state, ui = v.state, v.widgets
    spec = state.scene.probes
    changed, same = imgui.checkbox("Same on every axis", v.probe_axes_locked)
    if changed:
        v.probe_axes_locked = same
    if v.probe_axes_locked:
        changed, n = imgui.slider_int(C.PROBES_PER_AXIS.label, spec.grid[0], C.PROBES_PER_AXIS.lo,
                                     C.PROBES_PER_AXIS.hi)
        ui.note("Probes per axis")
        if changed:
            state.set_probe_grid((n, n, n))
    else:
        changed, grid = imgui.slider_int3("Probes x, y, z", list(spec.grid), 1, 64)
        ui.note("Probes x, y, z")
        if changed:
            state.set_probe_grid(tuple(grid))
    changed, n = imgui.slider_int(C.WALKS_PER_PROBE.label, spec.samples, C.WALKS_PER_PROBE.lo, C.WALKS_PER_PROBE.hi, "%d", imgui.SliderFlags_.logarithmic)
    ui.note("Walks per probe")
    if changed:
        state.set_probes(samples=max(1, n))
    changed, i = imgui.combo("SH window", SH_WINDOWS.index(spec.sh_window), list(SH_WINDOWS))
    if changed:
        state.set_probes(sh_window=SH_WINDOWS[i])
    changed, i = imgui.combo("Precision", PROBE_PRECISIONS.index(spec.precision), list(PROBE_PRECISIONS))
    if changed:
        state.set_probes(precision=PROBE_PRECISIONS[i])
    changed, i = imgui.combo("Grid covers", PROBE_FITS.index(spec.fit), ["visible region", "whole box"])
    if changed:
        state.set_probes(fit=PROBE_FITS[i])
    orders = ["auto", *SH_ORDERS]
    changed, i = imgui.combo("SH order", orders.index(spec.sh_order),
                             ["auto (0 when g = 0, more bands as |g| grows)", *map(str, SH_ORDERS)])
    if changed:
        state.set_probes(sh_order=orders[i])
    layout_section(v)
    auto_section(v)
    grid, session = v.session.probe_grid, v.session
    if grid is None:
        imgui.text_disabled("not baked yet (a probe method or the probe grid view bakes them)")
        return
    done = session.probes_ready()
    fraction = grid.passes_done / max(grid.passes_total, 1)
    label = "baked" if done else ("stale: bakes when a probe view is shown" if not state.wants_probes()
                                  else f"baking pass {grid.passes_done} / {grid.passes_total}")
    imgui.progress_bar(fraction if done or state.wants_probes() else 0.0, ImVec2(-1, 0), label)
    ui.note("bake progress")
    imgui.text(f"bake GPU time {session.bake_ms:.1f} ms over {grid.passes_done} passes")
    imgui.text(f"probe textures {grid.gpu_bytes / 2**20:.2f} MiB  (bake buffers {grid.bake_bytes / 2**20:.1f} MiB)")
    imgui.text(f"SH order {grid.sh_order}, {len(grid.textures)} textures"
               f"{', one channel (grey scene)' if grid.grey else ''}")
    rep = session.bake_report
    if rep is not None and rep.passes_done > 1:
        imgui.text_disabled(f"est. standard error of the probes {100 * rep.standard_error:.2f}%")


def layout_section(v) -> None:
    """Probe planes evenly spaced or adaptive (app/rendering/probes/planes.py): the indicator and the
    strength, applied when the slider is let go (each value re-places the planes and re-bakes)."""
    state, ui = v.state, v.widgets
    spec = state.scene.probes
    changed, i = imgui.combo("Interpolation", PROBE_INTERPOLATIONS.index(spec.interpolation),
                             ["trilinear", "visibility (no leaks through dense matter)"])
    ui.note("Interpolation")
    if changed:   # read-side only: no re-bake
        state.set_probes(interpolation=PROBE_INTERPOLATIONS[i])
    changed, i = imgui.combo("Layout", PROBE_LAYOUTS.index(spec.layout),
                             ["uniform", "adaptive (denser where it varies)"])
    ui.note("Layout")
    if changed:
        state.set_probes(layout=PROBE_LAYOUTS[i])
    if spec.layout != "adaptive":
        return
    changed, i = imgui.combo("Follows", PROBE_INDICATORS.index(spec.adaptive_indicator),
                             ["extinction (sigma_t)", "sun's transmittance"])
    if changed:
        state.set_probes(adaptive_indicator=PROBE_INDICATORS[i])
    shown = spec.adaptive_strength if v.adaptive_strength_edit is None else v.adaptive_strength_edit
    changed, value = imgui.slider_float("Strength", shown, 0.0, 1.0, "%.2f")
    ui.note("Strength")
    if changed:
        v.adaptive_strength_edit = float(value)
    if imgui.is_item_deactivated_after_edit() and v.adaptive_strength_edit is not None:
        state.set_probes(adaptive_strength=min(max(v.adaptive_strength_edit, 0.0), 1.0))
        v.adaptive_strength_edit = None
    grid = v.session.probe_grid
    if grid is not None and v.session.probes_ready():
        if grid.planes is None:
            imgui.text_disabled("planes evenly spaced: the indicator does not vary")
        else:
            spans = [np.diff(p) * len(p) for p in grid.planes if len(p) > 1]
            if spans:
                imgui.text_disabled(f"spacing {min(s.min() for s in spans):.2f} to "
                                    f"{max(s.max() for s in spans):.2f} x uniform")


def auto_section(v) -> None:
    """`auto`: measures the cheapest probe setting meeting a target error (app/rendering/probes/auto.py).
    It blocks while it measures (a pilot path trace and a few bakes)."""
    state, ui = v.state, v.widgets
    v.auto_target = getattr(v, "auto_target", 0.05)
    changed, t = imgui.slider_float("Auto target rRMSE", v.auto_target, 0.01, 0.3, "%.3f")
    if changed:
        v.auto_target = float(t)
    if imgui.button("Auto: cheapest probes meeting it"):
        from radiance_probes.rendering.probes.auto import choose_probes
        shown = REGISTRY[state.method]   # (refine's probes are its raymarcher's)
        method = shown.name if shown.needs_probes and not shown.composite else "raymarch"
        choice = choose_probes(v.session.renderer, v.auto_target, method)
        p = choice.scene.probes
        state.set_probes(grid=p.grid, samples=p.samples, sh_order=p.sh_order,
                         precision=p.precision, fit=p.fit)
        v.auto_report = choice.report()
    ui.note("Auto")
    if getattr(v, "auto_report", None):
        imgui.text_wrapped(v.auto_report.splitlines()[0])


def stats_section(v) -> None:
    session, t = v.session, v.session.last
    imgui.text(f"{v.device}")
    w, h = session.size
    imgui.text(f"render {w} x {h} px, window {v.framebuffer_size[0]} x {v.framebuffer_size[1]}")
    wall = session.pacer.wall
    if wall:
        frame = session.pacer.frame_ms
        imgui.text(f"frame {'?' if frame is None else f'{frame:.0f}'} ms wall clock (render "
                   f"{t.render_ms:.0f}, bake {t.bake_ms:.0f})")
        if t.bands:   # a sample longer than a frame, split into bands over frames
            imgui.text_wrapped(f"a sample over several frames: {t.tiles} tiles of 8 x 8 pixels "
                               f"in {t.bands} band{'s' if t.bands > 1 else ''} this frame")
    else:
        imgui.text(f"GPU frame {t.total_ms:.2f} ms (render {t.render_ms:.2f}, bake "
                   f"{t.bake_ms:.2f}, display {t.display_ms:.2f})")
    history = np.asarray(session.history, np.float64)
    if history.size and implot.begin_plot("##frame times", ImVec2(-1, 90 * v.ui_scale),
                                          implot.Flags_.no_menus | implot.Flags_.no_box_select
                                          | implot.Flags_.no_legend | implot.Flags_.no_inputs):
        implot.setup_axes("", "ms", implot.AxisFlags_.no_tick_labels, implot.AxisFlags_.auto_fit)
        implot.setup_axis_limits(implot.ImAxis_.x1, 0, max(len(history), 2), implot.Cond_.always)
        implot.plot_line("wall ms" if wall else "GPU ms", history)
        implot.end_plot()
    imgui.text_disabled(f"wall-clock time per frame: {session.pacer.reason}; the frames are paced "
                        "by it" if wall else "GPU time per frame from timestamp queries")
    parts = session.parts.last   # the frame before, part by part (app/viewer/frame/frame_parts.py)
    if parts:
        imgui.text_wrapped("last frame, GPU / wall ms: " + ", ".join(
            f"{name} {'-' if gpu is None else f'{gpu:.1f}'} / {w:.1f}"
            for name, (gpu, w) in sorted(parts.items(), key=lambda kv: -kv[1][1])))
    if t.filter_ms:
        imgui.text(f"denoise filter {t.filter_ms:.0f} ms on its own thread")
    if session.probe_grid is not None:
        imgui.text(f"bake {session.bake_ms:.1f} ms {'wall clock' if wall else 'GPU'}, probes "
                   f"{session.probe_grid.gpu_bytes / 2**20:.2f} MiB")


def camera_section(v) -> None:
    state, ui = v.state, v.widgets
    cam = state.scene.camera
    if imgui.button("Reset camera"):
        state.reset_camera()
    ui.note("Reset camera")
    changed, fov = imgui.slider_float("Field of view", cam.fov_y, 5.0, 120.0, "%.0f deg")
    if changed:
        state.set_camera(replace(cam, fov_y=float(fov)))
    imgui.text_disabled(f"eye ({cam.eye[0]:.2f}, {cam.eye[1]:.2f}, {cam.eye[2]:.2f})")
    changed, text = imgui.input_text("Screenshot", v.screenshot_path)
    if changed:
        v.screenshot_path = text
    if imgui.button("Save PNG"):
        v.request_screenshot()
    ui.note("Save PNG")
    changed, text = imgui.input_text("Scene file", v.scene_file)
    if changed:
        v.scene_file = text
    if imgui.button("Save scene"):
        v.save_scene()
    ui.note("Save scene")
    imgui.same_line()
    if imgui.button("Load scene"):
        v.open_path(v.scene_file)
    ui.note("Load scene")


def help_section(v) -> None:
    shortcut_table()


def slices_section(v) -> None:
    v.slices.section()


SECTIONS = (("Render", render_section), ("Slices", slices_section), ("Data", data_section), ("Time", time_section),
            ("Transfer function", transfer_panel),
            ("Crop and clip", crop_section), ("Light", light_section), ("Probes", probes_section),
            ("Bookmarks and movie", movie_section), ("Stats", stats_section),
            ("Camera and files", camera_section), ("Help (F1)", help_section))
CLOSED_AT_START = ("Help (F1)", "Slices", "Data", "Camera and files", "Crop and clip",
                   "Bookmarks and movie")
