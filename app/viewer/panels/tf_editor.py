"""The transfer function panel: colormap preset with a preview bar, the CT/MRI window (a preset or
level and width in data units), the opacity curve edited by dragging its control points over the
volume's histogram (ImPlot, its axis labelled in data units), density scale, albedo and
anisotropy."""
from __future__ import annotations

import numpy as np
import math
from dataclasses import replace

from imgui_bundle import ImVec2, imgui, implot

from radiance_probes.frontend.colorbar import (data_ticks as data_ticks)  # noqa: F401 (the panels import it from here)
from radiance_probes.io.scene_file import SceneError, load_transfer_function, save_transfer_function
from radiance_probes.scene.types import WINDOW_PRESETS
from radiance_probes.scene.transfer import ALIASES, COLORMAPS
from radiance_probes.scene.transfer_presets import colour_points_from, opacity_presets
from radiance_probes.viewer.state import add_point, move_point, remove_point

PRESETS = tuple(c for c in COLORMAPS if c not in ALIASES)
POINT_COLOUR = (1.0, 0.85, 0.2, 1.0)
HISTOGRAM_BINS = 128


def histogram_curve(volume, bins: int = HISTOGRAM_BINS,
                    channel: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Bin centres and log-scaled counts in [0, 1] of the normalised density (for a backdrop)."""
    counts = volume.histogram(bins, channel).astype(np.float64)
    logc = np.log1p(counts)
    height = logc / logc.max() if logc.max() > 0 else logc
    return (np.arange(bins) + 0.5) / bins, height


WINDOW_CHOICES = ("value range",) + tuple(WINDOW_PRESETS) + ("custom",)


def window_choice(window: tuple[float, float] | None) -> str:
    if window is None:
        return "value range"
    return next((k for k, w in WINDOW_PRESETS.items() if tuple(w) == tuple(window)), "custom")


def window_editor(v) -> None:
    """A CT/MRI window over the data (in its units: HU for CT): a preset, or level and width; the
    volume is renormalised with it (scene JSON volume.window; of several channels, the edited
    channel's own, channels[i].window)."""
    state, ui = v.state, v.widgets
    channels = state.scene.channels
    if channels:
        edited = v.edited_channel()
        vol = channels[edited]

        def set_window(**changes):
            state.set_channel(edited, **changes)
    else:
        vol = state.scene.volume

        def set_window(**changes):
            state.edit(volume=replace(vol, **changes))
    current = window_choice(vol.window)
    changed, index = imgui.combo("Window", WINDOW_CHOICES.index(current), list(WINDOW_CHOICES))
    ui.note("Window")
    if changed and WINDOW_CHOICES[index] != current:
        choice = WINDOW_CHOICES[index]
        if choice == "value range":
            window = None
        elif choice == "custom":
            lo, hi = v.edited_value_range()
            window = (0.5 * (lo + hi), hi - lo)
        else:
            window = WINDOW_PRESETS[choice]
        set_window(window=window, value_range=None)
    if vol.window is not None:
        level, width = (float(w) for w in vol.window)
        speed = max(width, 1e-6) / 200.0          # a 200-pixel drag moves by one width
        changed_l, new_level = imgui.drag_float("Level", level, speed, format="%.4g")
        ui.note("Level")
        changed_w, new_width = imgui.drag_float("Width", width, speed, format="%.4g")
        ui.note("Width")
        if changed_l or changed_w:
            new_level = float(new_level) if math.isfinite(new_level) else level
            new_width = float(new_width) if math.isfinite(new_width) and new_width > 0 else width
            if (new_level, new_width) != (level, width):
                set_window(window=(new_level, new_width))


def colour_bar(rgb: np.ndarray, width: float, height: float) -> None:
    """A horizontal bar of colours (n, 3) at the cursor."""
    draw = imgui.get_window_draw_list()
    p = imgui.get_cursor_screen_pos()
    n = len(rgb)
    for i, c in enumerate(rgb):
        col = imgui.get_color_u32((float(c[0]), float(c[1]), float(c[2]), 1.0))
        draw.add_rect_filled(ImVec2(p.x + width * i / n, p.y), ImVec2(p.x + width * (i + 1) / n + 1, p.y + height), col)
    imgui.dummy(ImVec2(width, height))


def transfer_panel(v) -> None:
    """The transfer function's editor and the medium's sliders; of several channels, one panel
    a channel (app/viewer/panels/channel_panel.py) with its switch, window and transfer function."""
    from radiance_probes.viewer.panels.channel_panel import channel_panels
    if v.state.scene.channels:
        channel_panels(v, transfer_editor)
    else:
        transfer_editor(v)
    medium_sliders(v)
    _transfer_file(v)


def transfer_editor(v) -> None:
    """The colours, window and opacity of the transfer function the editor shows
    (ViewerState.transfer_function: the edited channel's, or the scene's)."""
    state, ui = v.state, v.widgets
    tf = state.transfer_function
    width = imgui.get_content_region_avail().x
    if tf.rgba is not None:
        imgui.text_wrapped(f"The scene gives an explicit RGBA table ({len(tf.rgba)} rows): editing the "
                           "curve rewrites its opacity and keeps its colours; choosing a colormap "
                           "replaces its colours and keeps the curve.")
    if not state.scene.channels:
        _clinical_presets(v)
    current = ALIASES.get(tf.colormap, tf.colormap)
    names = list(PRESETS) if tf.colors is None else ["colour points", *PRESETS]
    shown = current if tf.colors is None else "colour points"
    changed, index = imgui.combo("Colormap", names.index(shown) if shown in names else 0, names)
    ui.note("Colormap")
    if changed and names[index] != "colour points":
        state.set_transfer(colormap=names[index])
    table = v.edited_table()
    if tf.colors is None:
        colour_bar(table[:, :3], width, 14 * v.ui_scale)
        if imgui.button("Edit colours as points"):
            state.set_transfer(colors=colour_points_from(table[:, :3]))
        ui.note("Edit colours as points")
    else:
        _colour_points_editor(v, width)
    window_editor(v)
    _opacity_presets(v)
    _opacity_editor(v, width)


def _clinical_presets(v) -> None:
    """The clinical CT presets (app/scene/clinical_presets.py): picking one replaces the colours and
    opacity, placed by the volume's window; data not in Hounsfield units says so instead."""
    from radiance_probes.scene.clinical_presets import CLINICAL_PRESETS, hounsfield_problem
    state, ui = v.state, v.widgets
    names = ["(none)", *CLINICAL_PRESETS]
    current = state.transfer_function.preset
    changed, index = imgui.combo("CT preset", names.index(current) if current in names else 0,
                                 names)
    ui.note("CT preset")
    if changed and index > 0:
        volume = v.session.volume
        problem = hounsfield_problem(volume)
        if problem is not None:
            state.error(f"the clinical preset {names[index]} is meant for Hounsfield units, but "
                        f"{problem}")
            return
        state.set_clinical_preset(names[index], state.scene.volume.domain or volume.value_range)


def medium_sliders(v) -> None:
    """density_scale, albedo and anisotropy (one each, whatever the channels), and the surface."""
    state, ui = v.state, v.widgets
    changed, value = imgui.slider_float("Density scale", state.scene.density_scale, 0.1, 10000.0, "%.1f",
                                        imgui.SliderFlags_.logarithmic)
    ui.note("Density scale")
    if changed:
        state.edit(density_scale=float(value))
    changed, value = imgui.slider_float("Albedo", state.scene.albedo, 0.0, 1.0)
    ui.note("Albedo")
    if changed:
        state.edit(albedo=float(value))
    changed, value = imgui.slider_float("Anisotropy g", state.scene.anisotropy, -0.95, 0.95)
    ui.note("Anisotropy g")
    if changed:
        state.edit(anisotropy=float(value))
    surface_sliders(v)


def surface_sliders(v) -> None:
    """The surfaces inside the volume (the scene's surface; glsl/lib/hybrid_scattering.glsl):
    gradient factor k (0: the phase function alone), roughness and a grey specular colour."""
    from radiance_probes.frontend import controls as C
    state, ui = v.state, v.widgets
    surface = state.scene.surface
    changed, value = imgui.slider_float(C.SURFACE_K.label, surface.gradient_factor, C.SURFACE_K.lo,
                                        C.SURFACE_K.hi, "%.3f",
                                        imgui.SliderFlags_.logarithmic)
    ui.note("Surface k")
    if changed:
        state.edit(surface=replace(surface, gradient_factor=max(float(value), 0.0)))
    if surface.gradient_factor > 0.0:
        changed, value = imgui.slider_float(C.ROUGHNESS.label, surface.roughness, C.ROUGHNESS.lo, C.ROUGHNESS.hi)
        ui.note("Roughness")
        if changed:
            state.edit(surface=replace(surface, roughness=float(value)))
        changed, value = imgui.slider_float("Specular", max(surface.specular), 0.0, 1.0)
        ui.note("Specular")
        if changed:
            state.edit(surface=replace(surface, specular=(float(value),) * 3))


def _transfer_file(v) -> None:
    """Save the transfer function on its own, or load one (JSON, the scene's key as a file)."""
    state, ui = v.state, v.widgets
    changed, text = imgui.input_text("TF file", v.transfer_file)
    ui.note("TF file")
    if changed:
        v.transfer_file = text
    if imgui.button("Save TF"):
        try:
            path = save_transfer_function(v.transfer_file, state.transfer_function)
            state.note(f"saved the transfer function to {path}")
        except OSError as exc:
            state.error(f"could not save the transfer function to {v.transfer_file}: {exc}")
    ui.note("Save TF")
    imgui.same_line()
    if imgui.button("Load TF"):
        try:
            state.set_edited_transfer(load_transfer_function(v.transfer_file))
            state.note(f"loaded the transfer function {v.transfer_file}")
        except SceneError as exc:
            state.error(str(exc))
    ui.note("Load TF")


def _opacity_presets(v) -> None:
    """Ramps, and tents over the histogram's peaks (transfer_presets.py), as the opacity curve."""
    state, ui = v.state, v.widgets
    volume = v.session.volume
    channel = v.edited_channel()
    cached = getattr(v, "_opacity_presets", {})
    if cached.get("volume") is not volume:
        cached = v._opacity_presets = {"volume": volume}
    if channel not in cached:
        cached[channel] = opacity_presets(volume, channel)
    presets = cached[channel]
    names = ["choose..."] + list(presets)
    changed, index = imgui.combo("Opacity preset", 0, names)
    ui.note("Opacity preset")
    if changed and index > 0:
        state.set_transfer(opacity=presets[names[index]])


POINT_MARKER = (10.0, 12.0)   # a colour point's marker under the bar, logical pixels


def _colour_points_editor(v, width: float) -> None:
    """The colour points on the bar they make: drag a marker along it, click one to pick its
    colour, right-click one to remove it, double-click the bar to add one there."""
    state, ui = v.state, v.widgets
    tf = state.transfer_function
    points = [list(p) for p in tf.colors]
    table = v.edited_table()
    s = v.ui_scale
    bar_h = 16 * s
    origin = imgui.get_cursor_screen_pos()
    colour_bar(table[:, :3], width, bar_h)
    ui.note("colour bar")
    if imgui.is_item_hovered() and imgui.is_mouse_double_clicked(imgui.MouseButton_.left):
        x = min(max((imgui.get_io().mouse_pos.x - origin.x) / width, 0.0), 1.0)
        rgb = table[int(round(x * (len(table) - 1))), :3]
        points.append([x, *map(float, rgb)])
        points.sort(key=lambda p: p[0])
        state.set_transfer(colors=tuple(map(tuple, points)))
        return
    draw = imgui.get_window_draw_list()
    mw, mh = POINT_MARKER[0] * s, POINT_MARKER[1] * s
    top = origin.y + bar_h + 1
    new = None
    for i, (x, r, g, b) in enumerate(points):
        cx = origin.x + x * width
        imgui.set_cursor_screen_pos(ImVec2(cx - mw / 2, top))
        imgui.invisible_button(f"##colour point {i}", ImVec2(mw, mh))
        ui.note_point(f"colour point {i}", cx, top + mh / 2)
        active = imgui.is_item_active()
        if active and imgui.is_mouse_dragging(imgui.MouseButton_.left, 2.0):
            v.colour_point_dragged = True    # a drag, not a click: no colour picker after it
            nx = min(max((imgui.get_io().mouse_pos.x - origin.x) / width, 0.0), 1.0)
            lo = points[i - 1][0] if i > 0 else 0.0
            hi = points[i + 1][0] if i + 1 < len(points) else 1.0
            new = [p[:] for p in points]
            new[i][0] = min(max(nx, lo), hi)
        elif imgui.is_item_deactivated():
            if not getattr(v, "colour_point_dragged", False):
                imgui.open_popup(f"colour point {i}")
            v.colour_point_dragged = False
        if imgui.is_item_clicked(imgui.MouseButton_.right) and len(points) > 1:
            new = [p for j, p in enumerate(points) if j != i]
        colour = imgui.get_color_u32((r, g, b, 1.0))
        edge = imgui.get_color_u32((1.0, 1.0, 1.0, 1.0) if active else (0.1, 0.1, 0.1, 1.0))
        a, b2, c = ImVec2(cx, top), ImVec2(cx - mw / 2, top + mh), ImVec2(cx + mw / 2, top + mh)
        draw.add_triangle_filled(a, b2, c, colour)
        draw.add_triangle(a, b2, c, edge, 1.5)
        if imgui.begin_popup(f"colour point {i}"):
            changed, rgb = imgui.color_picker3(f"##pick {i}", [r, g, b])
            if changed:
                new = [p[:] for p in points]
                new[i][1:] = [float(c) for c in rgb]
            imgui.end_popup()
    imgui.set_cursor_screen_pos(ImVec2(origin.x, top + mh + 4 * s))
    imgui.text_disabled(f"{len(points)} colour points: drag a marker, click it for its colour, "
                        "right-click removes, double-click the bar adds")
    if new is not None:
        state.set_transfer(colors=tuple(tuple(float(c) for c in p) for p in new))


def _opacity_editor(v, width: float) -> None:
    state, ui = v.state, v.widgets
    tf = state.transfer_function
    points, simplified_by = v.opacity_points()
    table_alpha = v.edited_table()[:, 3]   # what the renderers use
    xs, heights = v.histogram()
    flags = (implot.Flags_.no_menus | implot.Flags_.no_box_select | implot.Flags_.no_legend
             | implot.Flags_.no_mouse_text | implot.Flags_.no_title)
    if not implot.begin_plot("##opacity", ImVec2(width, 150 * v.ui_scale), flags):
        return
    axis_flags = implot.AxisFlags_.no_menus | implot.AxisFlags_.no_label
    implot.setup_axes("density", "opacity", axis_flags, axis_flags)
    implot.setup_axes_limits(0.0, 1.0, 0.0, 1.05, implot.Cond_.always)
    ticks, labels = data_ticks(v.edited_value_range())   # the x axis in data units
    implot.setup_axis_ticks(implot.ImAxis_.x1, ticks, labels)
    implot.plot_shaded("histogram", xs, heights, 0.0,
                       spec=implot.Spec(fill_color=(0.45, 0.55, 0.7, 1.0), fill_alpha=0.45))
    # The curve drawn is the scene's own opacity, from the table the renderers sample.
    line_x = np.linspace(0.0, 1.0, len(table_alpha))
    implot.plot_line("opacity", line_x, np.asarray(table_alpha, np.float64),
                     spec=implot.Spec(line_color=POINT_COLOUR, line_weight=2.0))
    new_points, any_hovered = points, False
    for i, (x, y) in enumerate(points):
        moved, nx, ny, _, hovered, _ = implot.drag_point(i, float(x), float(y), POINT_COLOUR, 6.0,
                                                         out_clicked=False, out_hovered=False, out_held=False)
        pixel = implot.plot_to_pixels(implot.Point(float(x), float(y)))
        ui.note_point(f"opacity point {i}", pixel.x, pixel.y)
        any_hovered = any_hovered or bool(hovered)
        if moved:
            new_points = move_point(new_points, i, nx, ny)
        if hovered and imgui.is_mouse_clicked(imgui.MouseButton_.right):
            new_points = remove_point(new_points, i)
            break
    if implot.is_plot_hovered() and not any_hovered and imgui.is_mouse_double_clicked(imgui.MouseButton_.left):
        m = implot.get_plot_mouse_pos()
        new_points = add_point(new_points, m.x, m.y)
    implot.end_plot()
    ui.note("opacity curve")
    if new_points != points:
        state.set_transfer(opacity=new_points)
    imgui.text_disabled("drag points; double-click adds one; right-click removes one; "
                        "the axis is in data units")
    if simplified_by > 0:
        imgui.text_disabled(f"{len(points)} points stand for the table's {len(tf.rgba)} rows "
                            f"(up to {simplified_by:.3f} apart); an edit keeps only these points")


def heat_legend(width: float, height: float, heat_max: float) -> None:
    from radiance_probes.viewer.display import heat_colours
    colour_bar(heat_colours(64), width, height)
    imgui.text_disabled(f"0{' ' * 6}per-pixel error / rms(pt){' ' * 6}{heat_max:g}")
