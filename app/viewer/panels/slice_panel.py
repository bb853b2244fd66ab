"""The slice view in the window: a column at the window's right holds the three orthogonal slices
(or one, bigger) through the point the state keeps (ViewerState.slice_point), coloured by the
window or the renderer's transfer function, with the crop box's rectangle, the clip plane's line,
what they cut away darkened, the other slices' lines, and the value under the mouse in data units.
A click (or a drag) in a slice moves the other slices and the orbit's centre to the voxel under it;
the wheel steps the slice. The 3D view shows where the slices lie. Maths: slice_view.py.

The slices' pixels are drawn with GL before the panels (SliceImages, glsl/slice_image.frag: one
texel a voxel, fetched unfiltered; ImGui 1.92's backend binds a linear sampler for its images,
which would blur the voxels into each other), the lines and words over them with ImGui."""
from __future__ import annotations

import math

import moderngl
import numpy as np
from imgui_bundle import ImVec2, imgui

from radiance_probes.gl.shaders import render_program, set_uniforms
from radiance_probes.viewer import orbit
from radiance_probes.viewer.crop_handles import kept_box
from radiance_probes.viewer.overlays import CROP_COLOUR, PLANE_COLOUR
from radiance_probes.viewer.slice_view import (AXES, AXIS_COLOURS, SLICE_COLOURS, SLICE_VIEWS,
                                               column_width, crop_rect, describe_voxel, edge_labels,
                                               fit_rect, image_shape, pixel_voxel, plane_extent,
                                               plane_segment, slice_boxes, slice_coord, slice_image,
                                               slice_indices, slice_name, slice_outline, slice_rgba,
                                               slice_world_points, voxel_centre, world_pixels)

CAPTION_PIXELS = 20.0          # the caption above a slice and the value line below it
BOX_GAP = 3.0                  # between a slice's box and its neighbours


class SliceImages:
    """Draws a slice's texture into a rectangle of the bound framebuffer, one texel a voxel."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.program = render_program(ctx, "fullscreen.vert", "slice_image.frag")
        self.vao = ctx.vertex_array(self.program, [])

    def draw(self, texture, rect) -> None:
        """`rect`: (x, y, w, h) in framebuffer pixels, GL's bottom-left origin."""
        x, y, w, h = rect
        x0, y0 = math.floor(x), math.floor(y)
        texture.use(0)
        set_uniforms(self.program, {"slice_image": 0,
                                    "image_rect": tuple(float(c) for c in rect)})
        self.ctx.viewport = (x0, y0, max(math.ceil(x + w) - x0, 1), max(math.ceil(y + h) - y0, 1))
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND | moderngl.CULL_FACE)
        self.vao.render(moderngl.TRIANGLES, vertices=3)

    def release(self) -> None:
        for obj in (self.vao, self.program):
            obj.release()


class SlicePanel:
    def __init__(self, viewer):
        self.viewer = viewer
        self._textures: dict[int, tuple] = {}    # axis -> (key, moderngl texture)
        self.hovered: dict | None = None         # the voxel under the mouse last frame

    # ---- what is shown -------------------------------------------------------------------------
    @property
    def mode(self) -> str:
        return self.viewer.state.slice_view

    def width(self) -> float:
        v = self.viewer
        return column_width(self.mode, v.window_size, v.sidebar_width())

    def column(self) -> tuple[float, float, float, float]:
        w, h = self.viewer.window_size
        width = self.width()
        return (w - width, 0.0, width, float(h))

    def volume(self):
        """The volume whose voxels the slices show: the one loaded (level 0) where it is in host
        memory, else the one shown; None for a volume read brick by brick."""
        res = self.viewer.session.renderer.resources
        for vol in (res.given_volume, res.volume):
            if vol is not None and isinstance(vol.data, np.ndarray):
                return vol
        return None

    def indices(self, volume) -> tuple[int, int, int]:
        return slice_indices(self.viewer.state.slice_point, volume.dims, volume.half_extent)

    def layout(self, volume) -> list[tuple[int, tuple, tuple]]:
        """(axis, box, image rectangle) of each slice shown, window coordinates."""
        s = self.viewer.ui_scale
        out = []
        for axis, (x, y, w, h) in slice_boxes(self.mode, self.column()):
            box = (x + BOX_GAP, y + BOX_GAP, w - 2 * BOX_GAP, h - 2 * BOX_GAP)
            area = (box[0], box[1] + CAPTION_PIXELS * s, box[2],
                    max(box[3] - 2 * CAPTION_PIXELS * s, 1.0))
            out.append((axis, box, fit_rect(area, plane_extent(axis, volume.half_extent))))
        return out

    def image_rect(self, axis: str) -> tuple[float, float, float, float]:
        """Where the slice across `axis` ("x", "y" or "z") is drawn; KeyError where it is not."""
        volume = self.volume()
        rects = {} if volume is None else {AXES[a]: r for a, _, r in self.layout(volume)}
        if axis not in rects:
            raise KeyError(f"no slice {axis!r} is shown (shown: {', '.join(rects) or 'none'})")
        return rects[axis]

    # ---- the mouse -----------------------------------------------------------------------------
    def at(self, x: float, y: float) -> tuple[int, tuple[int, int, int]] | None:
        """(axis, voxel) under a window point, None where no slice is."""
        volume = self.volume()
        if self.mode == "off" or volume is None:
            return None
        index = self.indices(volume)
        for axis, _, rect in self.layout(volume):
            voxel = pixel_voxel((x, y), rect, axis, index[axis], volume.dims)
            if voxel is not None:
                return axis, voxel
        return None

    def pick(self, x: float, y: float) -> bool:
        """A click or drag in a slice: the slices and the orbit's centre go to the voxel under
        it (its centre); False where no slice is under the point."""
        hit = self.at(x, y)
        if hit is None:
            return False
        volume = self.volume()
        point = voxel_centre(hit[1], volume.dims, volume.half_extent)
        state = self.viewer.state
        state.slice_point = tuple(float(c) for c in point)
        state.set_camera(orbit.recentre(state.scene.camera, point))
        return True

    def scroll(self, x: float, y: float, steps: float) -> bool:
        """The wheel over a slice steps it by whole voxels; False where no slice is."""
        hit = self.at(x, y)
        if hit is None or steps == 0:
            return False
        axis, voxel = hit
        self.step(axis, int(np.sign(steps)) * max(int(round(abs(steps))), 1))
        return True

    def step(self, axis: int, delta: int) -> None:
        volume = self.volume()
        if volume is None:
            return
        index = self.indices(volume)[axis] + delta
        self.set_index(axis, index)

    def set_index(self, axis: int, index: int) -> None:
        volume = self.volume()
        n = volume.dims[axis]
        point = list(self.viewer.state.slice_point)
        point[axis] = slice_coord(min(max(int(index), 0), n - 1), n, volume.half_extent[axis])
        self.viewer.state.slice_point = tuple(point)

    # ---- drawing -------------------------------------------------------------------------------
    def _texture(self, axis: int, volume, index: int):
        """The slice's texture, remade when what it shows changes."""
        v = self.viewer
        res = v.session.renderer.resources
        scene = res.scene
        mode = v.state.slice_colours
        table = res.table if res.tables is None else res.tables
        channel = v.edited_channel()
        key = (volume, volume.time, axis, index, mode, channel, scene.transfer_function,
               scene.channels, scene.crop, scene.clip_plane, id(table))
        kept_tex = self._textures.get(axis)
        if kept_tex is not None and kept_tex[0] == key:
            return kept_tex[1]
        if volume.channel_count == 1:
            densities = slice_image(volume.data, axis, index)
        else:
            order = ([channel] + [c for c in range(volume.channel_count) if c != channel]
                     if mode == "window" else range(volume.channel_count))
            densities = np.stack([slice_image(volume.channel(c), axis, index) for c in order], -1)
        from radiance_probes.scene.clip_region import clip_region
        region = clip_region(scene, volume.dims, volume.half_extent)
        kept = None if region is None else region.kept(
            slice_world_points(axis, index, volume.dims, volume.half_extent))
        rgba = slice_rgba(densities, mode, table, kept)
        rows, cols = image_shape(axis, volume.dims)
        tex = None if kept_tex is None else kept_tex[1]
        if tex is not None and tex.size != (cols, rows):
            tex.release()
            tex = None
        if tex is None:
            tex = v.ctx.texture((cols, rows), 4, rgba.tobytes())
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            tex.repeat_x = tex.repeat_y = False
        else:
            tex.write(rgba.tobytes())
        self._textures[axis] = (key, tex)
        return tex

    def render(self, images: SliceImages) -> None:
        """The slices' pixels, into the window's framebuffer (in render_frame, before the
        panels)."""
        volume = self.volume()
        if self.mode == "off" or volume is None:
            return
        v = self.viewer
        sx = v.framebuffer_size[0] / max(v.window_size[0], 1)
        sy = v.framebuffer_size[1] / max(v.window_size[1], 1)
        index = self.indices(volume)
        for axis, _, rect in self.layout(volume):
            x, y, w, h = rect
            images.draw(self._texture(axis, volume, index[axis]),
                        (x * sx, v.framebuffer_size[1] - (y + h) * sy, w * sx, h * sy))

    def draw(self) -> None:
        """What goes over the slices (captions, lines, the value under the mouse) and their
        outlines over the 3D view (in build_ui)."""
        self.hovered = None
        if self.mode == "off":
            self._drop_textures()
            return
        v = self.viewer
        volume = self.volume()
        draw = imgui.get_background_draw_list()
        x, y, w, h = self.column()
        if volume is None:
            draw.add_text(ImVec2(x + 8, y + 8), imgui.get_color_u32((1, 1, 1, 1)),
                          "no slices: the volume is read brick by brick")
            return
        scene = v.state.scene
        index = self.indices(volume)
        io = imgui.get_io()
        mouse = (io.mouse_pos.x, io.mouse_pos.y)
        free_mouse = not io.want_capture_mouse
        lo, hi = kept_box(scene, volume)
        crop_on = scene.crop is not None and scene.crop.enabled
        plane = scene.clip_plane if scene.clip_plane is not None and scene.clip_plane.enabled \
            else None
        s = v.ui_scale
        white = imgui.get_color_u32((1.0, 1.0, 1.0, 1.0))
        shown = []
        for axis, box, rect in self.layout(volume):
            shown.append(axis)
            coord = slice_coord(index[axis], volume.dims[axis], volume.half_extent[axis])
            bx, by, bw, bh = box
            colour = imgui.get_color_u32(AXIS_COLOURS[axis])
            draw.add_rect(ImVec2(bx, by), ImVec2(bx + bw, by + bh), colour, 0.0, 1.0)
            draw.add_text(ImVec2(bx + 4, by + 2), white,
                          f"{slice_name(axis, volume.direction)}  slice {index[axis]} / "
                          f"{volume.dims[axis] - 1}")
            rx, ry, rw, rh = rect
            draw.push_clip_rect(ImVec2(bx, by), ImVec2(bx + bw, by + bh), True)
            draw.push_clip_rect(ImVec2(rx, ry), ImVec2(rx + rw, ry + rh), True)
            for other in range(3):          # the other slices' lines through this one
                if other == axis:
                    continue
                p = voxel_centre(index, volume.dims, volume.half_extent)
                ends = np.array([p, p])
                along = 3 - axis - other
                ends[0, along], ends[1, along] = -volume.half_extent[along], volume.half_extent[along]
                (ax, ay), (bx2, by2) = world_pixels(ends, rect, axis, volume.half_extent)
                r, g, b, _ = AXIS_COLOURS[other]
                draw.add_line(ImVec2(ax, ay), ImVec2(bx2, by2),
                              imgui.get_color_u32((r, g, b, 0.55)), 1.0)
            if crop_on and lo[axis] <= coord <= hi[axis]:
                left, top, right, bottom = crop_rect(lo, hi, rect, axis, volume.half_extent)
                draw.add_rect(ImVec2(left, top), ImVec2(right, bottom),
                              imgui.get_color_u32(CROP_COLOUR), 0.0, 2.0 * s)
            if plane is not None:
                segment = plane_segment(plane.normal, plane.distance, lo, hi, axis, coord)
                if len(segment):
                    (ax, ay), (bx2, by2) = world_pixels(segment, rect, axis, volume.half_extent)
                    draw.add_line(ImVec2(ax, ay), ImVec2(bx2, by2),
                                  imgui.get_color_u32(PLANE_COLOUR), 2.0 * s)
            draw.pop_clip_rect()
            labels = edge_labels(axis, volume.direction)
            grey = imgui.get_color_u32((0.85, 0.85, 0.85, 1.0))
            for side, (tx, ty) in (("right", (rx + rw - 4, ry + rh / 2)),
                                   ("left", (rx + 4, ry + rh / 2)),
                                   ("top", (rx + rw / 2, ry + 2)),
                                   ("bottom", (rx + rw / 2, ry + rh - 2))):
                text = labels[side]
                size = imgui.calc_text_size(text)
                px = tx - (size.x if side == "right" else 0 if side == "left" else size.x / 2)
                py = ty - (size.y / 2 if side in ("left", "right") else
                           size.y if side == "bottom" else 0)
                draw.add_text(ImVec2(px, py), grey, text)
            voxel = pixel_voxel(mouse, rect, axis, index[axis], volume.dims) if free_mouse \
                else None
            if voxel is not None:
                text = describe_voxel(volume, voxel, scene)
                self.hovered = {"axis": AXES[axis], "voxel": list(voxel), "text": text,
                                "world": voxel_centre(voxel, volume.dims,
                                                      volume.half_extent).tolist()}
                draw.add_text(ImVec2(bx + 4, by + bh - CAPTION_PIXELS * s + 2), white, text)
            draw.pop_clip_rect()
            v.widgets.note_point(f"slice {AXES[axis]}", rx + rw / 2, ry + rh / 2)
        self._outlines(volume, index, shown)

    def _outlines(self, volume, index, shown) -> None:
        """Where the slices lie, outlined over the 3D view in their colours."""
        v = self.viewer
        if v.state.probe_view == "alone":
            return
        x, y, w, h = v.view_rect_window()
        draw = imgui.get_foreground_draw_list()
        draw.push_clip_rect(ImVec2(x, y), ImVec2(x + w, y + h), True)
        for axis in shown:
            coord = slice_coord(index[axis], volume.dims[axis], volume.half_extent[axis])
            pts = v.world_to_window(slice_outline(axis, coord, volume.half_extent))
            if len(pts) < 4 or not np.isfinite(pts).all():
                continue
            colour = imgui.get_color_u32(AXIS_COLOURS[axis])
            for i in range(4):
                draw.add_line(ImVec2(*pts[i]), ImVec2(*pts[(i + 1) % 4]), colour, 1.5 * v.ui_scale)
        draw.pop_clip_rect()

    # ---- the sidebar's section -----------------------------------------------------------------
    def section(self) -> None:
        v = self.viewer
        state, ui = v.state, v.widgets
        volume = self.volume()
        for label, choices, current, prefix, attr in (
                ("Slices", SLICE_VIEWS, state.slice_view, "slices ", "slice_view"),
                ("Colours", SLICE_COLOURS, state.slice_colours, "slice colours ", "slice_colours")):
            imgui.text(label)
            for i, choice in enumerate(choices):
                if i:
                    imgui.same_line()
                if imgui.radio_button(f"{choice}##{label}", current == choice):
                    setattr(state, attr, choice)
                ui.note(f"{prefix}{choice}")
        if volume is None:
            imgui.text_wrapped("no slices: the volume is read brick by brick")
            return
        index = self.indices(volume)
        for axis in range(3):
            n = volume.dims[axis]
            changed, value = imgui.slider_int(f"{slice_name(axis, volume.direction)} slice",
                                              index[axis], 0, n - 1)
            ui.note(f"slice {AXES[axis]} index")
            if changed:
                self.set_index(axis, value)
        if self.hovered is not None:
            imgui.text(self.hovered["text"])
        imgui.text_disabled("v: off, three slices, one; hover for the value in data units; a "
                            "click centres the slices and the orbit there; the wheel steps a "
                            "slice")

    # ---- for tests -----------------------------------------------------------------------------
    def snapshot(self) -> dict:
        volume = self.volume()
        return {"view": self.mode, "colours": self.viewer.state.slice_colours,
                "point": list(self.viewer.state.slice_point),
                "indices": None if volume is None else list(self.indices(volume)),
                "rects": {} if volume is None else
                {AXES[a]: list(rect) for a, _, rect in self.layout(volume)},
                "hovered": self.hovered}

    def _drop_textures(self) -> None:
        for _, tex in self._textures.values():
            tex.release()
        self._textures.clear()

    def release(self) -> None:
        self._drop_textures()
