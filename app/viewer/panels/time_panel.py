"""A time series' panel (SPEC.md, Time series): play and pause, a step back and forth, the time
slider and the playback rate. Each step is shown as a 3D volume; its probes start warm from the
step before (the probes cover the whole box: one grid for every step)."""
from __future__ import annotations

from imgui_bundle import imgui


def time_section(v) -> None:
    state, ui = v.state, v.widgets
    steps = v.time_steps
    if imgui.button("Pause" if state.playing else "Play"):
        v.toggle_playing()
    ui.note("Play")
    imgui.same_line()
    if imgui.button("<"):
        v.step_time(-1)
    ui.note("previous step")
    imgui.same_line()
    if imgui.button(">"):
        v.step_time(+1)
    ui.note("next step")
    imgui.same_line()
    imgui.text(f"step {state.scene.time} of 0..{steps - 1}")
    changed, step = imgui.slider_int("Time step", state.scene.time, 0, steps - 1)
    ui.note("Time step")
    if changed:
        state.playing = False
        state.set_time(step, steps)
    changed, rate = imgui.slider_float("Steps a second", state.play_rate, 1.0, 60.0, "%.0f")
    ui.note("Steps a second")
    if changed:
        state.play_rate = float(rate)
    res = v.session.renderer.resources
    imgui.text_disabled(f"steps kept for showing again: {res.steps_kept} (space plays, "
                        "',' and '.' step)")
