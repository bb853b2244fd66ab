"""The raymarcher's opacity-gradient grid (hybrid scattering, the scene's surface.gradient_factor
k > 0): grad A at every voxel centre, baked by glsl/opacity_gradient_bake.comp into an RGBA16F 3D
texture of the volume's own size, which glsl/lib/opacity_gradient_grid.glsl reads with one
trilinear fetch where the exact gradient takes six medium lookups (twin:
app/twins/opacity_gradient_grid.py). The raymarcher alone reads it; the path tracer, the walks and
`guided` keep the exact gradient. Like the light grid, an approximation baked once per edit of
the medium and measured for its bias (docs/design.md, Surfaces inside the volume)."""
from __future__ import annotations

import moderngl
import numpy as np

from radiance_probes.gl.shaders import ComputeProgram, compute_program, set_uniforms
from radiance_probes.gl.textures import device_available
from radiance_probes.rendering.resources import SceneResources

# Texture units: 0 volume, 1 transfer function, 2..8 probes, 9 light grid, 10 majorant grid,
# 11 and 15 passes' inputs read only while they run, 12 and 13 the environment map, 14 an
# adaptive layout's warp, 16 and 17 a brick pool's tables, 18 the denoiser's kept means.
GRADIENT_UNIT = 19
LOCAL_SIZE = 4                # opacity_gradient_bake.comp's work group: 4 x 4 x 4 voxels
BYTES_PER_VOXEL = 8           # RGBA16F (opacity_gradient_bake.comp says why 16 bits suffice)
# The grid's memory at most: a 512^3 volume's (the foot's 256^3 takes 128 MiB). Beyond it, or
# beyond half of what the device has left, the raymarcher computes the exact gradient (a larger
# grid would also cost a longer bake at every edit of the transfer function).
MAX_BYTES = 1 << 30


def grid_refusal(resources: SceneResources, max_bytes: int | None = None) -> str | None:
    """Why the raymarcher cannot read an opacity-gradient grid of this scene (it then computes the
    exact gradient); None where it can. `max_bytes`: the budget (None: MAX_BYTES)."""
    max_bytes = MAX_BYTES if max_bytes is None else max_bytes
    if not resources.scene.surface.gradient_factor > 0.0:
        return "no surfaces (k = 0): no gradient is read"
    if resources.bricked:
        # a volume too large for one texture, of whose 16- or 32-bit texels the grid's 8 bytes a
        # voxel would be 4 or 2 times the memory; no second approximation (a coarser grid, a grid
        # of bricks) stands in: the exact gradient reads the pool
        return "the volume is bricked: the exact gradient reads its brick pool"
    need = grid_bytes(resources.volume.dims)
    if need > max_bytes:
        return (f"the grid would take {need / 2**20:.0f} MiB, over its budget of "
                f"{max_bytes / 2**20:.0f} MiB")
    available, where = device_available(resources.ctx)
    if available is not None and need > available // 2:
        return (f"the grid would take {need / 2**20:.0f} MiB, over half the "
                f"{available / 2**20:.0f} MiB of {where}")
    return None


def grid_bytes(dims) -> int:
    """The grid's GPU bytes for a volume of `dims` voxels (one texel each)."""
    return BYTES_PER_VOXEL * int(np.prod(dims, dtype=np.int64))


class OpacityGradientGrid:
    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self._programs: dict[tuple, ComputeProgram] = {}   # per medium defines
        self.texture: moderngl.Texture3D | None = None
        self.key: tuple | None = None     # what the texture (or the refusal) is for
        self.refusal: str | None = None   # why there is no grid for `key` (None: there is one)
        self.builds = 0                   # bakes run (tests count them)
        self.cost_ms = 0.0                # GPU ms of the last bake (Renderer.bake_gradient_grid)

    @property
    def usable(self) -> bool:
        """Whether the texture holds the grid of `key`."""
        return self.key is not None and self.refusal is None and self.texture is not None

    def update(self, resources: SceneResources, key: tuple, max_bytes: int | None = None) -> bool:
        """Makes the grid of `key` (what it depends on: the caller's) from `resources`' medium,
        where it is stale: baked, or refused (grid_refusal; the texture then freed). True where a
        bake ran."""
        if key == self.key:
            return False
        self.key = key
        self.refusal = grid_refusal(resources, max_bytes)
        if self.refusal is not None:
            self._drop_texture()
            return False
        self._bake(resources)
        return True

    def forget(self) -> None:
        """The next update bakes again (its time is then real), the texture kept for it."""
        self.key = None

    def drop(self) -> None:
        """Gives the texture's memory back (surfaces switched off); the next update bakes anew."""
        self.key = None
        self._drop_texture()

    def _program(self, defines: dict) -> ComputeProgram:
        key = tuple(sorted(defines.items()))
        program = self._programs.get(key)
        if program is None:
            program = self._programs[key] = compute_program(self.ctx, "opacity_gradient_bake.comp",
                                                            defines)
        return program

    def _bake(self, resources: SceneResources) -> None:
        dims = tuple(int(n) for n in resources.volume.dims)
        if self.texture is None or self.texture.size != dims:
            self._drop_texture()
            self.texture = self.ctx.texture3d(dims, 4, dtype="f2")
            self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self.texture.repeat_x = self.texture.repeat_y = self.texture.repeat_z = False
        # the medium's defines (channels, crop or not, HYBRID_SCATTERING): the same medium code
        # as the raymarcher's
        program = self._program(resources.medium_defines())
        resources.bind()
        set_uniforms(program, resources.uniforms())
        set_uniforms(program, {"grid": dims})
        self.texture.bind_to_image(0, read=False, write=True)
        program.run(*(-(-n // LOCAL_SIZE) for n in dims))
        self.ctx.memory_barrier(moderngl.TEXTURE_FETCH_BARRIER_BIT)
        self.builds += 1

    def uniforms(self) -> dict:
        """What lib/opacity_gradient_grid.glsl reads besides the medium's uniforms."""
        return {"opacity_gradient_texture": GRADIENT_UNIT}

    def bind(self) -> None:
        self.texture.use(GRADIENT_UNIT)

    def read(self) -> np.ndarray:
        """The grid as float32 (nz, ny, nx, 3): grad A's x, y, z at each voxel centre."""
        w, h, d = self.texture.size
        texels = np.frombuffer(self.texture.read(), np.float16).reshape(d, h, w, 4)
        return texels[..., :3].astype(np.float32)

    @property
    def gpu_bytes(self) -> int:
        return 0 if self.texture is None else grid_bytes(self.texture.size)

    def _drop_texture(self) -> None:
        if self.texture is not None:
            self.texture.release()
        self.texture = None

    def release(self) -> None:
        self._drop_texture()
        for program in self._programs.values():
            program.release()
        self._programs.clear()
