"""The 'Bookmarks and movie' panel: the scene's bookmarks (go, save the view over one, delete,
add; shift+N and ctrl+N from the keyboard) and the movie recorder: a turntable or a flight through
the bookmarks, its method, samples, size and file, recorded with the probes baked once."""
from __future__ import annotations

from imgui_bundle import ImVec2, imgui

from radiance_probes.methods import MOVIE_METHODS as METHODS
from radiance_probes.viewer.recorder import MOVIE_MODES


def movie_section(v) -> None:
    state, ui = v.state, v.widgets
    marks = state.scene.bookmarks
    if not marks:
        imgui.text_disabled("no bookmarks yet: ctrl+1 .. ctrl+9 saves the view as one")
    for i, mark in enumerate(marks, start=1):
        if imgui.button(f"{i}: {mark.name}##go{i}"):
            state.go_to_bookmark(i)
        ui.note(f"bookmark {i}")
        imgui.same_line()
        if imgui.small_button(f"save view##{i}"):
            state.save_bookmark(i)
        imgui.same_line()
        if imgui.small_button(f"delete##{i}"):
            state.delete_bookmark(i)
            break
    if imgui.button("Add the view as a bookmark"):
        state.save_bookmark()
    ui.note("Add bookmark")
    imgui.separator()
    m = v.movie
    changed, i = imgui.combo("Movie", MOVIE_MODES.index(m["mode"]),
                             ["turntable", "fly through the bookmarks"])
    if changed:
        m["mode"] = MOVIE_MODES[i]
    if m["mode"] == "turntable":
        changed, value = imgui.slider_float("Degrees", float(m["degrees"]), -720.0, 720.0, "%.0f")
        if changed:
            m["degrees"] = value
    changed, value = imgui.slider_int("Frames", int(m["frames"]), 2, 1200)
    ui.note("Frames")
    if changed:
        m["frames"] = max(2, value)
    changed, i = imgui.combo("Movie method", METHODS.index(m["method"]), list(METHODS))
    if changed:
        m["method"] = METHODS[i]
    changed, value = imgui.slider_int("Samples per frame", int(m["spp"]), 1, 1024, "%d",
                                      imgui.SliderFlags_.logarithmic)
    ui.note("Samples per frame")
    if changed:
        m["spp"] = max(1, value)
    changed, size = imgui.input_int2("Size", [int(m["width"]), int(m["height"])])
    if changed:
        m["width"], m["height"] = (max(2, int(s) // 2 * 2) for s in size)
    changed, text = imgui.input_text("Movie file", m["out"])
    ui.note("Movie file")
    if changed:
        m["out"] = text
    changed, on = imgui.checkbox("Colour bar", bool(m["colorbar"]))
    if changed:
        m["colorbar"] = on
    imgui.text_disabled(".mp4, .gif, or a folder for numbered PNGs")
    recorder = v.recorder
    if imgui.button("Stop recording" if recorder is not None else "Record movie (ctrl+r)"):
        v.toggle_recording()
    ui.note("Record movie")
    if recorder is not None:
        p = recorder.progress()
        imgui.progress_bar(p["done"] / max(p["total"], 1), ImVec2(-1, 0),
                           f"frame {p['done']} / {p['total']}")
