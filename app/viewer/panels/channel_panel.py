"""One panel a channel (SPEC.md, Channels): its switch, its colour, and, opened, its window and
transfer function in the same editor a one-channel volume has (app/viewer/panels/tf_editor.py), which
edits the channel the panel names while it draws (ViewerState.channel)."""
from __future__ import annotations

from imgui_bundle import ImVec2, imgui


def channel_label(i: int, channel) -> str:
    return f"Channel {i}" + (f": {channel.name}" if channel.name else "")


def channel_panels(v, editor) -> None:
    """Each channel's panel; `editor(v)` draws the transfer-function editor of the channel the
    state's `channel` names. The widget names a script clicks are prefixed "channel i "."""
    state, ui = v.state, v.widgets
    chosen = state.channel
    imgui.text_disabled("channels add up: extinctions add, colours mix by extinction")
    for i, channel in enumerate(state.scene.channels):
        imgui.push_id(f"channel {i}")
        ui.prefix = f"channel {i} "
        try:
            state.channel = i
            _swatch(v, i)
            imgui.same_line()
            changed, on = imgui.checkbox("##shown", channel.enabled)
            ui.note("shown")
            if changed:
                state.set_channel(i, enabled=bool(on))
            imgui.same_line()
            imgui.set_next_item_open(i == 0, imgui.Cond_.once)
            opened = imgui.tree_node(channel_label(i, channel))
            ui.note("panel")
            if opened:
                editor(v)
                imgui.tree_pop()
        finally:
            ui.prefix = ""
            imgui.pop_id()
    state.channel = chosen


def _swatch(v, i: int) -> None:
    """The channel's colour where its opacity is largest (its table's)."""
    res = v.session.renderer.resources
    if res.tables is None or i >= res.tables.count:
        imgui.dummy(ImVec2(12 * v.ui_scale, 12 * v.ui_scale))
        return
    table = res.tables.tables[i]
    r, g, b = (float(c) for c in table[int(table[:, 3].argmax()), :3])
    imgui.color_button("##colour", (r, g, b, 1.0), imgui.ColorEditFlags_.no_tooltip,
                       ImVec2(12 * v.ui_scale, 12 * v.ui_scale))
