"""The sun's transmittance baked on a grid over the box (glsl/light_transmittance.comp), which the
raymarcher reads instead of tracing a shadow ray per step."""
from __future__ import annotations

import moderngl

from ..gl.shaders import compute_program, set_uniforms
from .resources import SceneResources

LIGHT_UNIT = 9
LIGHT_MARCH_VOXELS = 2.0   # march step in half voxels (resources.march_step)
MIN_SIDE = 128  # texels along the volume's longest axis at least (small volumes are upsampled)
MAX_SIDE = 512  # texels per axis at most; the volume's own resolution up to that
# Texels per probe spacing at least, along the longest axis: the sun's transmittance from the grid
# is the raymarcher's direct light and the walks' sun, and its interpolation error must stay below
# the probes' own. Measured on the H100 (bench/h100-light): bonsai at 128^3 probes, raymarch rRMSE
# 3.38% with the volume's 256 texels, 2.55% at 384, 2.24% at 512 (foot 1.43 / 1.03 / 0.91%); at
# 64^3 probes 5.77 / 5.04 / 4.74%; the grid takes 9 / 30 / 70 ms.
TEXELS_PER_PROBE = 6


def light_grid_size(dims: tuple[int, int, int], max_side: int = MAX_SIDE,
                    min_side: int = MIN_SIDE) -> tuple[int, int, int]:
    """Texels per axis: the volume's resolution, upsampled so that the longest axis has at least
    min_side (the sun's transmittance varies inside a voxel: on fuel, 64^3, the RMS error of the
    sun at scattering points falls from 6.8% at 64^3 to 1.6% at 128^3), at most max_side per axis."""
    scale = max(1.0, min_side / max(dims))
    return tuple(int(min(max(1, round(d * scale)), max_side)) for d in dims)


def min_side_for_probes(probe_grid: tuple[int, int, int] | None, floor: int = MIN_SIDE) -> int:
    """The light grid's least texels along the longest axis for a probe grid (None: no probes),
    and at least `floor`."""
    return max(floor, TEXELS_PER_PROBE * max(probe_grid)) if probe_grid else floor


# On a CPU rasterizer the light grid keeps the volume's own resolution: upsampling a 24^3 test
# volume's grid to 128^3 took 0.9 s per bake on llvmpipe's two cores against 12 ms, and every
# light, transfer-function or probe edit re-bakes it.
SOFTWARE_MIN_SIDE = 1


class LightTransmittance:
    def __init__(self, ctx: moderngl.Context, max_side: int = MAX_SIDE):
        self.ctx = ctx
        self.max_side = int(max_side)
        self.program = compute_program(ctx, "light_transmittance.comp",
                                       {"SUN_MARCH_SKIPS_EMPTY_CELLS": 1})
        self.texture: moderngl.Texture3D | None = None
        self.grid = (0, 0, 0)
        self.next_layer = 0

    def begin(self, resources: SceneResources, min_side: int = MIN_SIDE) -> None:
        """Starts a bake that bake_layers() does a slab of z layers at a time (the viewer's
        budgeted frames); until it is done the texture holds new layers below next_layer and the
        previous grid's above (texels are independent: each marches to the sun on its own)."""
        grid = light_grid_size(resources.volume.dims, self.max_side, min_side)
        if self.texture is None or self.texture.size != grid:
            if self.texture is not None:
                self.texture.release()
            self.texture = self.ctx.texture3d(grid, 1, dtype="f4")
            self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self.texture.repeat_x = self.texture.repeat_y = self.texture.repeat_z = False
        self.grid = grid
        self.next_layer = 0

    @property
    def done(self) -> bool:
        return self.texture is not None and self.next_layer >= self.grid[2]

    def bake_layers(self, resources: SceneResources, layers: int | None = None) -> int:
        """Bakes the next `layers` z layers (None: all that are left); returns how many ran."""
        grid = self.grid
        first = self.next_layer
        count = grid[2] - first if layers is None else max(0, min(int(layers), grid[2] - first))
        if count == 0:
            return 0
        resources.bind()
        set_uniforms(self.program, resources.uniforms())
        # Quadrature every voxel (the probes' march takes half voxels): the grid's own interpolation
        # error dominates; measured on bonsai at 256^3, RMS error of the sun's transmittance at
        # scattering points 7.6% against 7.4%, for half the time.
        set_uniforms(self.program, {"grid": grid, "first_layer": first,
                                    "march_step": LIGHT_MARCH_VOXELS * resources.march_step})
        self.texture.bind_to_image(0, read=False, write=True)
        self.program.run((grid[0] + 3) // 4, (grid[1] + 3) // 4, (count + 3) // 4)
        self.ctx.memory_barrier(moderngl.TEXTURE_FETCH_BARRIER_BIT)
        self.next_layer = first + count
        return count

    @property
    def gpu_bytes(self) -> int:
        return 0 if self.texture is None else 4 * self.texture.width * self.texture.height * self.texture.depth

    def bind(self) -> None:
        self.texture.use(LIGHT_UNIT)

    def release(self) -> None:
        self.program.release()
        if self.texture is not None:
            self.texture.release()
