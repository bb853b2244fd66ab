"""The macrocell majorant grid on the GPU (empty-space skipping; see app/twins/majorant_grid.py).

Per volume, the density range of every macrocell is computed with NumPy and uploaded once (RG32F);
whenever the transfer function or density_scale changes, glsl/majorant_grid.comp turns it into the
majorant grid (R32F 3D texture, bound to MAJORANT_UNIT and read by glsl/lib/tracking.glsl with
texelFetch)."""
from __future__ import annotations

import weakref

import moderngl
import numpy as np

from radiance_probes.scene.clip_region import ClipRegion, region_uniforms
from radiance_probes.gl.shaders import ComputeProgram, compute_program, set_uniforms
from radiance_probes.gl.textures import TransferTable
from radiance_probes.scene.channels import channel_uniforms
from radiance_probes.twins.majorant_grid import (MAJORANT_SAFETY, brick_density_range_grid,
                                                 channel_density_ranges, density_range_grid,
                                                 macrocell_counts, majorant_bound)
from radiance_probes.io.volume import Volume

# Texture units: 0 volume, 1 transfer function (and its storage buffer, binding 8), 2..8 probes, 9 light transmittance (raymarcher).
MAJORANT_UNIT = 10   # the majorant grid, read by the tracking passes
RANGE_UNIT = 11      # the density ranges, read only while the grid is built

RANGE_MAX_UNIT = 15  # several channels: their largest densities, read only while the grid is built

_programs: "weakref.WeakKeyDictionary[moderngl.Context, dict[int, ComputeProgram]]" = \
    weakref.WeakKeyDictionary()


def _program(ctx: moderngl.Context, channels: int = 1) -> ComputeProgram:
    """One compiled build pass per context and channel count (every SceneResources shares it)."""
    programs = _programs.setdefault(ctx, {})
    program = programs.get(channels)
    if program is None:
        defines = {"MEDIUM_CHANNELS": channels} if channels > 1 else None
        program = programs[channels] = compute_program(ctx, "majorant_grid.comp", defines)
    return program


def density_ranges(volume: Volume, cells: tuple[int, int, int] | None = None):
    """(cells, (least, largest) density per macrocell) of a volume: NumPy, no GL (a volume
    opening in the viewer has them made on its loading thread: 0.8 s for the foot), kept in
    volume.derived (a step of a series seen before costs nothing)."""
    cells = macrocell_counts(volume.dims) if cells is None else tuple(int(c) for c in cells)
    ranges = volume.derived.get(("density ranges", cells))
    if ranges is None:
        if not isinstance(volume.data, np.ndarray):   # read brick by brick: its ranges
            store = volume.bricks
            ranges = brick_density_range_grid(*store.ranges(), store.dims, store.brick, cells)
        else:
            ranges = (channel_density_ranges(volume, cells) if volume.channel_count > 1
                      else density_range_grid(volume.data, cells))
        volume.derived[("density ranges", cells)] = ranges
    return cells, ranges


class MajorantGrid:
    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.cells: tuple[int, int, int] | None = None
        self.range_tex: moderngl.Texture3D | None = None
        self.range_max_tex: moderngl.Texture3D | None = None   # several channels only
        self.channels = 1
        self.texture: moderngl.Texture3D | None = None
        self.d_min: np.ndarray | None = None
        self.d_max: np.ndarray | None = None
        self.bound = 0.0      # >= every cell's majorant; 0 when the whole volume is transparent
        self.builds = 0       # how many times the grid was built on the GPU (tests count them)

    def set_volume(self, volume: Volume, cells: tuple[int, int, int] | None = None) -> None:
        """The density range per macrocell of a new volume (density_ranges); of several
        channels, each channel's ([C, cz, cy, cx]; on the GPU one texture of the least and one
        of the largest, a component a channel). `cells`: macrocells per axis (None: the volume's
        own, macrocell_counts; the bake's coarser level takes the level shown's, bake_level.py)."""
        cells, ranges = density_ranges(volume, cells)
        channels = volume.channel_count
        self.d_min, self.d_max = ranges
        if channels > 1:
            payloads = [np.ascontiguousarray(np.moveaxis(r, 0, -1), np.float32)
                        for r in (self.d_min, self.d_max)]
        else:
            payloads = [np.ascontiguousarray(np.stack([self.d_min, self.d_max], axis=-1),
                                             np.float32)]
        if self.cells != cells or self.channels != channels:
            for tex in (self.range_tex, self.range_max_tex, self.texture):
                if tex is not None:
                    tex.release()
            self.range_tex = self.ctx.texture3d(cells, 2 if channels == 1 else channels, dtype="f4")
            self.range_max_tex = (self.ctx.texture3d(cells, channels, dtype="f4")
                                  if channels > 1 else None)
            self.texture = self.ctx.texture3d(cells, 1, dtype="f4")
            for tex in (self.range_tex, self.range_max_tex, self.texture):
                if tex is not None:
                    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
                    tex.repeat_x = tex.repeat_y = tex.repeat_z = False
            self.cells, self.channels = cells, channels
        self.range_tex.write(payloads[0].tobytes())
        if channels > 1:
            self.range_max_tex.write(payloads[1].tobytes())

    def build(self, transfer: TransferTable, table, density_scale: float,
              transfer_unit: int, clip: ClipRegion | None = None, half_extent=None) -> None:
        """Majorant per macrocell under the current transfer function and density_scale (GPU);
        with a crop or clip plane (`clip`, in the box of `half_extent`) cells cut away get 0."""
        program = _program(self.ctx, self.channels)
        transfer.use(transfer_unit)
        self.range_tex.use(RANGE_UNIT)
        if self.channels > 1:
            self.range_max_tex.use(RANGE_MAX_UNIT)
            set_uniforms(program, {"density_range_max": RANGE_MAX_UNIT,
                                   **channel_uniforms(table)})
        else:
            set_uniforms(program, {"transfer_size": int(len(table))})
        set_uniforms(program, {"density_range": RANGE_UNIT, "transfer_function": transfer_unit,
                               "density_scale": float(density_scale), "cells": self.cells,
                               "majorant_safety": float(MAJORANT_SAFETY),
                               **region_uniforms(clip)})
        if clip is not None:
            set_uniforms(program, {"box_half_extent": tuple(float(v) for v in half_extent)})
        self.texture.bind_to_image(0, read=False, write=True)
        program.run(*((c + 3) // 4 for c in self.cells))
        self.ctx.memory_barrier(moderngl.TEXTURE_FETCH_BARRIER_BIT
                                | moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)
        self.bound = majorant_bound(self.d_min, self.d_max, table, density_scale)
        self.builds += 1

    def read(self) -> np.ndarray:
        """The grid as float32 [cz, cy, cx] (tests compare it with app/twins/majorant_grid.py)."""
        cx, cy, cz = self.cells
        return np.frombuffer(self.texture.read(), np.float32).reshape(cz, cy, cx).copy()

    @property
    def gpu_bytes(self) -> int:
        texel = 12 if self.channels == 1 else 4 + 8 * self.channels
        return 0 if self.cells is None else texel * int(np.prod(self.cells))

    def bind(self) -> None:
        self.texture.use(MAJORANT_UNIT)

    def release(self) -> None:
        for tex in (self.range_tex, self.range_max_tex, self.texture):
            if tex is not None:
                tex.release()
        self.range_tex = self.range_max_tex = self.texture = None
