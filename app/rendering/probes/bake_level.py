"""The medium the probes' bake walks at RenderSettings.bake_level k > 0: the volume shown, k levels
coarser (volume_placement.coarser: an OME-Zarr store's own level, else 2 x 2 x 2 voxels averaged),
in the same world box, in one 3D texture of its own with its own majorant grid (its densities'
ranges over the level shown's macrocells).

What the probes hold is computed in it: the walks, their sun (the bake's own light grid, or the
shadow rays of walk_sun "ray" and of the grid's correction) and the probes' own sun (channel 27).
What the image reads directly stays on the level shown: camera rays, the sun at the image's points
(the raymarcher's light grid, the shadow rays of `probes`), the path tracer, and where the probes
sit (the visible region, an adaptive layout's planes). A shortcut with a bias: docs/bricking.md
states it, measured against the path tracer (lab/experiments/experiment_bake_level.py).

The coarser level must fit one 3D texture (of a 2048^3 store, level 1 is 1024^3): where it does
not, bake_level is refused with the sizes, never half built. It is not counted against
volume_memory_bytes (the cap chooses the level shown); BakeMedium.gpu_bytes says what it takes.

bake_level -1 ("by the probes' spacing", spacing_level): the coarsest level whose voxel is no larger
than half the probe spacing along every axis, so that a probe cell spans two of its voxels at least
(Nyquist for what the probes can hold); level 0 where even the level shown is coarser than that.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from radiance_probes.io.brick_layout import DEFAULT_BRICK_SIZE, texel_bytes
from radiance_probes.io.bricks import HOST_WHOLE_BYTES
from radiance_probes.gl.textures import check_volume_fits, device_available, volume_texture
from radiance_probes.io.volume import Volume, VolumeError
from radiance_probes.rendering.cache_keys import majorant_grid_key
from radiance_probes.rendering.grids.majorant_grid import MajorantGrid
from radiance_probes.rendering.resources import TRANSFER_UNIT, VOLUME_UNIT, SceneResources
from radiance_probes.rendering.levels.volume_placement import coarser

SPACING_LEVEL = -1   # bake_level: the level the probes' spacing allows (spacing_level)
MAX_BAKE_LEVEL = 8   # 256x coarser: past any volume the renderer takes


def check_bake_level(value) -> int:
    """The bake level asked for (an integer from -1 to MAX_BAKE_LEVEL), or ValueError naming
    bake_level."""
    if isinstance(value, bool) or not isinstance(value, int) or not (
            SPACING_LEVEL <= value <= MAX_BAKE_LEVEL):
        raise ValueError(f"bake_level: expected an integer from 0 (the level shown) to "
                         f"{MAX_BAKE_LEVEL} (levels coarser for the probes' bake), or "
                         f"{SPACING_LEVEL} (by the probes' spacing), got {value!r}")
    return value


def level_dims(volume: Volume, levels: int) -> list[tuple[int, int, int]]:
    """Voxels per axis (x, y, z) of the volume and its next `levels` coarser levels, as
    volume_placement.coarser makes them (an OME-Zarr store's own levels first, then halving with
    an odd axis rounded up), without reading any."""
    dims = [tuple(volume.dims)]
    own = list(volume.levels or ())
    for _ in range(levels):
        if own:
            z, y, x = own.pop(0).shape[:3]
            dims.append((int(x), int(y), int(z)))
        else:
            dims.append(tuple((n + 1) // 2 for n in dims[-1]))
    return dims


def spacing_level(volume: Volume, grid, box=None, max_level: int = MAX_BAKE_LEVEL) -> int:
    """The coarsest level whose voxel is no larger than half the probe spacing along every axis
    (the probes' box / their count per axis; an adaptive layout's planes are taken at their mean
    spacing): a probe cell then spans two of that level's voxels at least. 0 where the level shown
    is already coarser than that. `box`: the probes' (low, high) world corners (None: the
    volume's box)."""
    he = np.asarray(volume.half_extent, np.float64)
    size = 2.0 * he if box is None else np.asarray(box[1], np.float64) - np.asarray(box[0],
                                                                                     np.float64)
    half_spacing = 0.5 * size / np.asarray(grid, np.float64)
    level = 0
    for k, dims in enumerate(level_dims(volume, max_level)[1:], start=1):
        voxel = 2.0 * he / np.asarray(dims, np.float64)
        if not np.all(voxel <= half_spacing * (1.0 + 1e-9)):
            break
        level = k
    return level


def coarse_volume(volume: Volume, level: int, max_side: int, available: int | None,
                  where: str) -> Volume:
    """`volume` `level` levels coarser, in host memory, checked to fit one 3D texture before any
    of it is read; VolumeError naming bake_level and the sizes where it does not."""
    dims = level_dims(volume, level)[-1]
    channels = volume.channel_count
    # an OME-Zarr level keeps the store's type; an averaged one is float32
    exact = volume.exact_uint8 and len(volume.levels or ()) >= level
    texel = texel_bytes(channels, exact)
    need = int(np.prod(np.asarray(dims, np.int64))) * texel
    nx, ny, nz = volume.dims
    shown = f"{nx} x {ny} x {nz}"
    try:
        check_volume_fits(volume.name, dims, texel, max_side, available, where)
        from_store = len(volume.levels or ()) >= level   # the store's own level: read whole
        if from_store and 4 * int(np.prod(np.asarray(dims, np.int64))) * channels > HOST_WHOLE_BYTES:
            raise VolumeError(f"its {need / 2**30:.2f} GiB are more than the "
                              f"{HOST_WHOLE_BYTES / 2**30:.0f} GiB read whole into host memory")
    except VolumeError as exc:
        raise VolumeError(
            f"bake_level {level}: the bake's level ({dims[0]} x {dims[1]} x {dims[2]}, "
            f"{need / 2**20:.1f} MiB, {level} below the level shown, {shown}) must fit one 3D "
            f"texture and does not: {exc}. Use a larger bake_level or 0") from None
    brick = volume.bricks.brick if volume.bricks is not None else DEFAULT_BRICK_SIZE
    current = volume
    for _ in range(level):
        current = coarser(current, brick)
    data = current.data if isinstance(current.data, np.ndarray) else np.asarray(current.data)
    return dataclasses.replace(current, data=data, bricks=None, derived={})


class BakeMedium:
    """The scene's resources as the bake sees them at a bake level k > 0: the level shown's
    (SceneResources: transfer table, lights, environment map, clip, statistics) with the volume
    texture and the majorant grid of the level k coarser in their place (its densities over the
    level shown's macrocells) (the same texture units,
    so every bake pass reads it through lib/medium.glsl unchanged). Anything else is the shown
    resources' own."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.shown: SceneResources | None = None
        self.level = 0
        self.volume: Volume | None = None
        self.volume_tex = None
        self.majorant_grid = MajorantGrid(ctx)
        self._key: tuple | None = None
        self._majorant_key: tuple | None = None

    def __getattr__(self, name):   # what is not the coarse level's: the shown resources'
        shown = self.__dict__.get("shown")
        if shown is None:
            raise AttributeError(name)
        return getattr(shown, name)

    def update(self, shown: SceneResources, level: int) -> "BakeMedium":
        """The coarse level of what `shown` shows now, made (or kept) for `level` > 0; its
        majorant grid rebuilt where the transfer function, density scale or clip changed."""
        key = (id(shown), shown.volume_version, level)
        if key != self._key:
            max_side = int(self.ctx.info["GL_MAX_3D_TEXTURE_SIZE"])
            available, where = device_available(self.ctx)
            volume = coarse_volume(shown.volume, level, max_side, available, where)
            texture = volume_texture(self.ctx, volume)
            if self.volume_tex is not None:
                self.volume_tex.release()
            self.volume, self.volume_tex, self.level = volume, texture, level
            # the level shown's macrocells (the same cells in the world box): the coarse level's
            # own (half as many per axis) let a small dense feature's majorant cover 8 times the
            # volume around it (llvmpipe, the battery's speck at 20 voxels: a bake 2x longer at
            # level 1, 2.7x at level 2, than at level 0)
            self.majorant_grid.set_volume(volume, shown.majorant_grid.cells)
            self._majorant_key = None
            self._key = key
        self.shown = shown
        s = shown.scene
        majorant_key = (key, shown.clip, majorant_grid_key(s))
        if majorant_key != self._majorant_key:
            self.majorant_grid.build(shown.transfer_gpu, shown.medium_table, s.density_scale,
                                     TRANSFER_UNIT, clip=shown.clip,
                                     half_extent=shown.volume.half_extent)
            self._majorant_key = majorant_key
        return self

    @property
    def bricked(self) -> bool:
        return False   # one texture (coarse_volume refuses a level that needs bricks)

    def medium_defines(self) -> dict:
        return SceneResources.medium_defines(self)

    def defines(self) -> dict:
        return SceneResources.defines(self)

    @property
    def march_step(self) -> float:
        """Half the coarse level's smallest voxel side (the bake's marches step at its voxels)."""
        return SceneResources.march_step.fget(self)

    def uniforms(self) -> dict:
        """The shown resources' uniforms, with the coarse level's majorant grid bound and without
        a brick pool's (the world box is the shown volume's: coarser() keeps it)."""
        u = self.shown.uniforms()
        if self.shown.bricked:
            for name in self.shown.volume_tex.uniforms():
                u.pop(name, None)
        u["volume_density"] = VOLUME_UNIT
        u["majorant_grid_bound"] = float(self.majorant_grid.bound)
        if "surface_gradient_step" in u:   # the gradient over the coarse level's voxels
            he, dims = self.volume.half_extent, self.volume.dims
            u["surface_gradient_step"] = tuple(float(2.0 * he[i] / dims[i]) for i in range(3))
        return u

    def bind(self) -> None:
        self.shown.bind()
        self.volume_tex.use(VOLUME_UNIT)
        self.majorant_grid.bind()

    @property
    def gpu_bytes(self) -> int:
        """GPU bytes of the coarse level: its texture and its majorant grid."""
        if self.volume is None:
            return 0
        texel = texel_bytes(self.volume.channel_count, self.volume.exact_uint8)
        return int(np.prod(self.volume.dims, dtype=np.int64)) * texel + self.majorant_grid.gpu_bytes

    def release(self) -> None:
        if self.volume_tex is not None:
            self.volume_tex.release()
        self.volume_tex, self.volume, self._key, self._majorant_key = None, None, None, None
        self.majorant_grid.release()
