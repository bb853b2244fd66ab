"""The 'Crop and clip' panel: the crop box per axis (voxels, or world units where the scene gives
them so), the clip plane's direction and distance, on/off for each, and the handles over the view
(key x toggles both, h the handles)."""
from __future__ import annotations

import numpy as np
from imgui_bundle import imgui

from radiance_probes.viewer.state import angles_from_direction, direction_from_angles


def crop_section(v) -> None:
    state, ui = v.state, v.widgets
    scene = state.scene
    volume = v.session.volume
    dims = volume.dims
    crop = scene.crop
    changed, on = imgui.checkbox("Crop box", crop is not None and crop.enabled)
    ui.note("Crop box")
    if changed:
        if crop is None:
            state.set_crop((0, 0, 0), tuple(dims), "voxels", enabled=on)
        else:
            state.set_crop(crop.min, crop.max, crop.units, enabled=on)
        crop = state.scene.crop
    if crop is not None:
        he = np.asarray(volume.half_extent, np.float64)
        lo, hi = list(crop.min), list(crop.max)
        for a, axis in enumerate("xyz"):
            if crop.units == "voxels":
                changed, values = imgui.slider_int2(f"{axis} voxels", [int(lo[a]), int(hi[a])], 0,
                                                    int(dims[a]))
            else:
                changed, values = imgui.slider_float2(f"{axis} (world)", [float(lo[a]), float(hi[a])],
                                                      float(-he[a]), float(he[a]), "%.3f")
            ui.note(f"crop {axis}")
            if changed:
                lo[a], hi[a] = values
                state.set_crop(lo, hi, crop.units, enabled=crop.enabled)
        kept = (f"voxels {list(crop.min)} to {list(crop.max)} (max exclusive)"
                if crop.units == "voxels" else "world units")
        imgui.text_disabled(f"keeps {kept}; a crop on voxel boundaries renders as the cropped "
                            "volume does")
        if imgui.button("Whole volume"):
            state.set_crop((0, 0, 0), tuple(dims), "voxels", enabled=True)
        ui.note("Whole volume")
    imgui.separator()
    plane = scene.clip_plane
    changed, on = imgui.checkbox("Clip plane", plane is not None and plane.enabled)
    ui.note("Clip plane")
    if changed:
        state.set_clip_plane(enabled=on)
        plane = state.scene.clip_plane
    if plane is not None:
        normal = np.asarray(plane.normal, np.float64)
        length = float(np.linalg.norm(normal))
        az, el = angles_from_direction(normal / length)
        changed_a, az = imgui.slider_float("Normal azimuth", az, -180.0, 180.0, "%.0f deg")
        ui.note("Normal azimuth")
        changed_e, el = imgui.slider_float("Normal elevation", el, -90.0, 90.0, "%.0f deg")
        ui.note("Normal elevation")
        if changed_a or changed_e:
            state.set_clip_plane(normal=direction_from_angles(az, el),
                                 distance=plane.distance / length)
        changed, d = imgui.slider_float("Distance", plane.distance / length, -0.9, 0.9, "%.3f")
        ui.note("Clip distance")
        if changed:
            state.set_clip_plane(normal=tuple(normal / length), distance=d)
        if imgui.button("Flip side"):
            state.set_clip_plane(normal=tuple(-normal), distance=-plane.distance)
        ui.note("Flip side")
        imgui.text_disabled("keeps the points x with dot(n, x) <= distance (world units)")
    imgui.separator()
    changed, shown = imgui.checkbox("Handles over the view (h)", state.show_handles)
    ui.note("Handles")
    if changed:
        state.show_handles = shown
    imgui.text_disabled("drag a handle to move a face or the plane; x turns cropping on and off")
