"""The viewer's ImGui panels: the sidebar, channels, crop, movie, slices, time, the transfer-function editor."""
