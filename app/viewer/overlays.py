"""What floats over the picture: the method labels, the help window, the error panel and the
built-in file browser."""
from __future__ import annotations

from imgui_bundle import ImVec2, imgui

from radiance_probes.methods import REFERENCE
from radiance_probes.viewer.input import GROUP_HELP, MOUSE_HELP, SHORTCUTS

ERROR_COLOUR = (1.0, 0.45, 0.4, 1.0)


def shortcut_table() -> None:
    if imgui.begin_table("shortcuts", 2, imgui.TableFlags_.row_bg):
        for keys, what in (*MOUSE_HELP, *((s.keys, s.what) for s in SHORTCUTS if s.listed),
                           *GROUP_HELP):
            imgui.table_next_row()
            imgui.table_next_column()
            imgui.text(keys)
            imgui.table_next_column()
            imgui.text(what)
        imgui.end_table()


def help_window(v) -> None:
    if not v.state.show_help:
        return
    imgui.set_next_window_pos(ImVec2(v.view_rect_window()[0] + 20, 20), imgui.Cond_.appearing)
    expanded, still_open = imgui.begin("Keyboard and mouse", True, imgui.WindowFlags_.always_auto_resize)
    if expanded:
        shortcut_table()
    imgui.end()
    if not still_open:
        v.state.show_help = False


def error_window(v) -> None:
    state = v.state
    if not state.errors:
        return
    x, y, w, h = v.view_rect_window()
    imgui.set_next_window_pos(ImVec2(x + 10, y + h - 10), imgui.Cond_.always, ImVec2(0, 1))
    imgui.set_next_window_size(ImVec2(max(w - 20, 200), 0))
    imgui.push_style_color(imgui.Col_.title_bg, (0.5, 0.1, 0.1, 1.0))
    imgui.push_style_color(imgui.Col_.title_bg_active, (0.6, 0.12, 0.12, 1.0))
    imgui.begin("Errors", None, imgui.WindowFlags_.no_collapse | imgui.WindowFlags_.no_move)
    for text in state.errors:
        imgui.push_style_color(imgui.Col_.text, ERROR_COLOUR)
        imgui.text_wrapped(text)
        imgui.pop_style_color()
    if imgui.button("Dismiss"):
        state.errors.clear()
    v.widgets.note("Dismiss")
    imgui.end()
    imgui.pop_style_color(2)


def file_browser(v) -> None:
    files = v.files
    if not files.browser_open:
        return
    imgui.set_next_window_size(ImVec2(460 * v.ui_scale, 380 * v.ui_scale), imgui.Cond_.appearing)
    expanded, still_open = imgui.begin("Open a scene or a volume", True)
    if expanded:
        imgui.text_wrapped(str(files.browser_dir))
        if imgui.button("Up"):
            files.browser_dir = files.browser_dir.parent
        imgui.same_line()
        if imgui.button("Open this folder"):   # a TIFF stack or a DICOM series
            files.browser_open = False
            v.open_path(str(files.browser_dir))
        v.widgets.note("Open this folder")
        imgui.same_line()
        imgui.text_disabled("no system file dialog (zenity, kdialog) found; this is the built-in one")
        imgui.begin_child("entries", ImVec2(0, 0))
        for p in files.entries():
            label = f"[{p.name}]" if p.is_dir() else p.name
            clicked, _ = imgui.selectable(label, False)
            v.widgets.note(f"browser {p.name}")
            if clicked:
                if p.is_dir():
                    files.browser_dir = p
                else:
                    files.browser_open = False
                    v.open_path(str(p))
        imgui.end_child()
    imgui.end()
    if not still_open:
        files.browser_open = False


def view_labels(v) -> None:
    """The methods and sample counts over the view (not over the sidebar)."""
    state = v.state
    x, y, w, _ = v.view_rect_window()
    draw = imgui.get_foreground_draw_list()
    shown = state.shown_methods()

    def label(px: float, text: str) -> None:
        size = imgui.calc_text_size(text)
        draw.add_rect_filled(ImVec2(px - 4, y + 4), ImVec2(px + size.x + 4, y + 8 + size.y),
                             imgui.get_color_u32((0.0, 0.0, 0.0, 0.55)))
        draw.add_text(ImVec2(px, y + 6), imgui.get_color_u32((1.0, 1.0, 1.0, 1.0)), text)

    if state.probe_view == "alone":
        label(x + 8, "probe grid")
    elif state.display == "split" and len(shown) > 1:
        label(x + 8, v.session.label(state.method))
        right = v.session.label(state.split_method)
        label(x + w - imgui.calc_text_size(right).x - 12, right)
    elif state.display == "error" and state.method != REFERENCE:
        rmse = v.error_meter.value
        label(x + 8, f"|{state.method} - pt|  rel. RMSE {rmse:.4f}  (pt {v.error_meter.samples[1]} spp)")
    else:
        label(x + 8, v.session.label(state.method))


CROP_COLOUR = (1.0, 0.8, 0.25, 0.95)
PLANE_COLOUR = (0.35, 0.85, 1.0, 0.95)


def crop_overlay(v) -> None:
    """The crop box's edges and the clip plane's outline over the view, with their handles (drag
    one to move that face or the plane; 'h' hides them)."""
    from radiance_probes.viewer.crop_handles import kept_box, plane_polygon
    state = v.state
    scene = state.scene
    crop_on = scene.crop is not None and scene.crop.enabled
    plane_on = scene.clip_plane is not None and scene.clip_plane.enabled
    if not state.show_handles or not (crop_on or plane_on) or state.probe_view == "alone":
        return
    volume = v.session.volume
    lo, hi = kept_box(scene, volume)
    x, y, w, h = v.view_rect_window()
    draw = imgui.get_foreground_draw_list()
    draw.push_clip_rect(ImVec2(x, y), ImVec2(x + w, y + h), True)
    scale = v.ui_scale
    if crop_on:
        corners = [[(lo, hi)[(k >> a) & 1][a] for a in range(3)] for k in range(8)]
        pts = v.world_to_window(corners)
        colour = imgui.get_color_u32(CROP_COLOUR)
        for i in range(8):
            for a in range(3):
                j = i | (1 << a)
                if j != i:
                    draw.add_line(ImVec2(*pts[i]), ImVec2(*pts[j]), colour, 1.5 * scale)
    if plane_on:
        outline = plane_polygon(scene.clip_plane.normal, scene.clip_plane.distance, lo, hi)
        if len(outline):
            pts = v.world_to_window(outline)
            colour = imgui.get_color_u32(PLANE_COLOUR)
            for i in range(len(pts)):
                draw.add_line(ImVec2(*pts[i]), ImVec2(*pts[(i + 1) % len(pts)]), colour,
                              2.0 * scale)
    mouse = imgui.get_io().mouse_pos
    for mark, (hx, hy) in v.handle_points():
        colour = CROP_COLOUR if mark.kind == "crop" else PLANE_COLOUR
        hovered = (mouse.x - hx) ** 2 + (mouse.y - hy) ** 2 <= (9.0 * scale) ** 2
        radius = (7.0 if hovered else 5.5) * scale
        draw.add_circle_filled(ImVec2(hx, hy), radius, imgui.get_color_u32(colour))
        draw.add_circle(ImVec2(hx, hy), radius, imgui.get_color_u32((0.1, 0.1, 0.1, 1.0)),
                        0, 1.5 * scale)
        v.widgets.note_point(f"handle {mark.name}", hx, hy)
    draw.pop_clip_rect()


def probe_tooltip(v) -> None:
    """The probe view's probe under the mouse: which it is and what it holds (viewer.py
    hovered_probe), in a tooltip by the cursor."""
    if v.state.probe_view == "off" or imgui.get_io().want_capture_mouse:
        return
    mouse = imgui.get_io().mouse_pos
    hovered = v.hovered_probe((mouse.x, mouse.y))
    v.last_hovered_probe = hovered
    if hovered is None:
        return
    imgui.begin_tooltip()
    for line in hovered["lines"]:
        imgui.text(line)
    imgui.end_tooltip()
