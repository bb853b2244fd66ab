"""The area lights' optical-depth grid (glsl/area_light_transmittance.comp, read by
glsl/lib/area_light_grid.glsl; twin app/twins/area_light_grid.py): for every enabled light, the
optical depth from each texel towards the light's centre, over the box the sun's light grid covers.
The raymarcher and probes-only read it for the lights' direct single scattering (they trace no
shadow rays); the path tracer, `probes` and the walks trace theirs. Baked when those first need it
and again when the medium or an enabled light changes (cache_keys.area_light_grid_key), whole: at
most MAX_SIDE texels per axis a light, one march each (docs/design.md, Area lights, its cost)."""
from __future__ import annotations

import math

import moderngl
import numpy as np

from radiance_probes.scene.area_lights import enabled_lights
from radiance_probes.gl.shaders import ComputeProgram, compute_program, set_uniforms
from radiance_probes.rendering.grids.light_transmittance import LIGHT_MARCH_VOXELS, covered_box
from radiance_probes.rendering.resources import SceneResources

# Texture units: 0 volume, 1 transfer function, 2..8 probes, 9 light grid, 10 majorant grid,
# 11 and 15 passes' inputs, 12 and 13 the environment map, 14 an adaptive layout's warp, 16 and
# 17 a brick pool's tables, 18 the denoiser's kept means, 19 the opacity-gradient grid.
AREA_LIGHT_UNIT = 20
LOCAL_SIZE = (8, 8, 4)   # area_light_transmittance.comp's work group
# Texels per axis a light, at most (the volume's resolution up to that, never upsampled): each
# texel marches its own ray across the box, a voxel a step, so a bake costs up to texels x the
# volume's side in medium lookups (128^3 over a 256^3 volume: about 0.4 G), less where the
# majorant grid skips empty space (the chest CT with ct_bone: 1.5x faster). With the near march
# at a voxel's spacing (lib/area_light_grid.glsl) the resolution matters little where it was
# measured: on llvmpipe, the chest CT with ct_bone (256 x 133 x 256 voxels) at 40 x 40 pixels and
# 8^3 probes under a far small sphere light, the raymarcher's rRMSE against the path tracer is
# 3.43 / 3.45 / 3.86% with 32 / 64 / 128 texels along the longest axis, against 3.99% under the
# sun (its grid at the volume's 256); 128 on a GPU, as the sun's grid's least, for shadow detail
# at 1080p that 40 x 40 pixels cannot show. On a CPU rasterizer fewer (a 32-side bake there takes
# 0.06 s, 128 about 2 s).
MAX_SIDE = 128
SOFTWARE_MAX_SIDE = 32
# The methods that read it (the others trace shadow rays towards the lights).
AREA_GRID_METHODS = ("raymarch", "probes-only")


def area_light_grid_max_side(software: bool) -> int:
    return SOFTWARE_MAX_SIDE if software else MAX_SIDE


def grid_size(dims, max_side: int) -> tuple[int, int, int]:
    """Texels per axis of one light's block: the covered voxels, scaled down so that the longest
    axis has at most max_side."""
    scale = min(1.0, max_side / max(dims))
    return tuple(max(1, int(round(d * scale))) for d in dims)


class AreaLightGrid:
    def __init__(self, ctx: moderngl.Context, max_side: int = MAX_SIDE):
        self.ctx = ctx
        self.max_side = int(max_side)
        self._programs: dict[tuple, ComputeProgram] = {}   # per medium defines
        self.texture: moderngl.Texture3D | None = None
        self.key: tuple | None = None   # what the texture holds
        self.size = (0, 0, 0)           # texels per axis of one light's block
        self.count = 0                  # lights (blocks stacked along z)
        self.half_extent = np.zeros(3)
        self.centre = np.zeros(3)
        self.march_step = 1.0
        self.builds = 0                 # bakes run (tests count them)
        self.cost_ms = 0.0              # GPU ms of the last bake (the renderer's timer)

    def _program(self, defines: dict) -> ComputeProgram:
        key = tuple(sorted(defines.items()))
        if key not in self._programs:
            self._programs[key] = compute_program(self.ctx, "area_light_transmittance.comp",
                                                  defines)
        return self._programs[key]

    def compile(self, resources: SceneResources) -> ComputeProgram:
        """The bake's program for `resources`' medium (compiled once; before a timed bake)."""
        return self._program({**resources.medium_defines(), "AREA_LIGHTS": 1})

    def update(self, resources: SceneResources, key: tuple) -> bool:
        """Bakes the grid of `key` (the caller's: Renderer._area_light_grid_key) where the texture
        holds another; True where a bake ran."""
        if key == self.key:
            return False
        dims, half, centre = covered_box(resources)
        self.size = grid_size(dims, self.max_side)
        self.count = len(enabled_lights(resources.scene))
        self.half_extent, self.centre = np.asarray(half, np.float64), np.asarray(centre, np.float64)
        self.march_step = LIGHT_MARCH_VOXELS * resources.march_step
        stacked = (self.size[0], self.size[1], self.size[2] * self.count)
        if self.texture is None or self.texture.size != stacked:
            if self.texture is not None:
                self.texture.release()
            self.texture = self.ctx.texture3d(stacked, 1, dtype="f2")
            self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self.texture.repeat_x = self.texture.repeat_y = self.texture.repeat_z = False
        program = self.compile(resources)
        resources.bind()
        set_uniforms(program, resources.uniforms())
        set_uniforms(program, {**self.uniforms(), "first_layer": 0})
        self.texture.bind_to_image(0, read=False, write=True)
        program.run(math.ceil(stacked[0] / LOCAL_SIZE[0]), math.ceil(stacked[1] / LOCAL_SIZE[1]),
                    math.ceil(stacked[2] / LOCAL_SIZE[2]))
        self.ctx.memory_barrier(moderngl.TEXTURE_FETCH_BARRIER_BIT)
        self.key = key
        self.builds += 1
        return True

    def forget(self) -> None:
        """The next update bakes again (the bench charges every image its grid)."""
        self.key = None

    def uniforms(self) -> dict:
        """What lib/area_light_grid.glsl reads besides the lights' own uniforms."""
        texel = float(np.max(2.0 * self.half_extent / np.asarray(self.size, np.float64)))
        return {"area_light_transmittance": AREA_LIGHT_UNIT, "area_light_grid_size": self.size,
                "area_light_grid_centre": tuple(self.centre),
                "area_light_grid_half_extent": tuple(self.half_extent),
                "area_light_grid_texel": texel, "area_light_grid_march_step": self.march_step}

    def bind(self) -> None:
        self.texture.use(AREA_LIGHT_UNIT)

    def read(self) -> np.ndarray:
        """The optical depths (light, z, y, x)."""
        nx, ny, nz = self.size
        data = np.frombuffer(self.texture.read(), np.float16).astype(np.float32)
        return data.reshape(self.count, nz, ny, nx)

    @property
    def gpu_bytes(self) -> int:
        t = self.texture
        return 0 if t is None else 2 * t.width * t.height * t.depth

    def release(self) -> None:
        for program in self._programs.values():
            program.release()
        self._programs.clear()
        if self.texture is not None:
            self.texture.release()
            self.texture = None
