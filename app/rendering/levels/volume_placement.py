"""Where a volume goes on the GPU: one 3D texture (app/gl/textures.py volume_texture) where it
fits, else a brick pool (app/gl/brick_pool.py) of the finest level whose bricks that are not
constant fit the memory cap (RenderSettings.volume_memory_bytes, else the memory the device has
left) and one atlas texture: the level shown whole, so every method renders one medium. A volume
longer than GL_MAX_3D_TEXTURE_SIZE along an axis is bricked, not refused."""
from __future__ import annotations

import dataclasses

import moderngl
import numpy as np

from radiance_probes.twins.majorant_grid import macrocell_counts
from radiance_probes.rendering.levels.level_mix import mixed_density_ranges, mixed_plan
from radiance_probes.io.brick_layout import (DEFAULT_BRICK_SIZE, brick_counts, slot_bytes,
                                             slot_grid, texel_bytes)
from radiance_probes.io.brick_sources import (ArraySource, box_filtered, source_box_filtered,
                                              source_whole)
from radiance_probes.io.bricks import BrickStore, LazyData, PoolPlan, refuse_cap_below_brick
from radiance_probes.io.level_bound import bound_level, varying_bricks
from radiance_probes.gl.brick_pool import upload_plan
from radiance_probes.gl.textures import device_available, volume_texture
from radiance_probes.io.volume import Volume, VolumeError


def _gib(n: int) -> str:
    if n >= 2**30:
        return f"{n / 2**30:.2f} GiB"
    return f"{n / 2**20:.1f} MiB" if n >= 2**20 else f"{n / 2**10:.1f} KiB"


def _store(volume: Volume, brick: int) -> BrickStore:
    if volume.bricks is not None and volume.bricks.brick == brick:
        return volume.bricks
    source = (ArraySource(volume.data) if isinstance(volume.data, np.ndarray)
              else volume.bricks.source)
    return BrickStore(source, brick, volume.name)


def coarser(volume: Volume, brick: int) -> Volume:
    """The next level: the store's own (OME-Zarr multiscales), else 2 x 2 x 2 voxels averaged
    (in host memory); the same world box (spacing scaled by the dims' ratio)."""
    if volume.levels:
        source = volume.levels[0]
        store = BrickStore(source, brick, volume.name)
        data, levels, dtype = LazyData(store), volume.levels[1:], volume.raw_dtype
    else:
        store = None
        data = (box_filtered(volume.data) if isinstance(volume.data, np.ndarray)
                else source_box_filtered(volume.bricks.source, brick))
        levels, dtype = (), "float32"   # averages are no longer 8-bit values
    nz, ny, nx = data.shape[:3]
    spacing = tuple(float(s) * n / m for s, n, m in zip(volume.spacing, volume.dims,
                                                          (nx, ny, nz)))
    return dataclasses.replace(volume, data=data, spacing=spacing, raw_dtype=dtype,
                               derived={}, bricks=store, levels=levels)


def level_bytes(store: BrickStore, channels: int, exact_uint8: bool, max_side: int) -> int | None:
    """GPU bytes of a store's pool (atlas, page table, constants); None where its atlas exceeds
    one 3D texture."""
    resident = store.resident_count()
    try:
        grid = slot_grid(resident, store.brick, max_side)
    except ValueError:
        return None
    constants = int(np.count_nonzero(store.constant())) + 1
    return (int(np.prod(grid)) * slot_bytes(store.brick, channels, exact_uint8)
            + _table_bytes(store, constants))


def _table_bytes(store: BrickStore, constants: int) -> int:
    """A pool's bytes besides its atlas: the page table (a texel a brick) and `constants` rows."""
    return 4 * int(np.prod(brick_counts(store.dims, store.brick))) + 16 * constants


def _resident_at_least(volume: Volume, store: BrickStore, bounds: dict):
    """(a lower bound on `store`'s bricks that are not constant, the coarser level's source it
    was read from) from the volume's own coarser levels (app/io/level_bound.py), without the
    store's range pass; None where no level of the store can tell."""
    source = bound_level(volume.dims, volume.levels, store.brick)
    if source is None:
        return None
    if id(source) not in bounds:
        bounds[id(source)] = source_whole(source)
    varying = varying_bricks(bounds[id(source)], volume.dims, store.brick)
    return int(np.count_nonzero(varying)), source


def _may_fit(at_least, store: BrickStore, channels: int, exact_uint8: bool, max_side: int,
             cap: int) -> bool:
    """Whether a level with at least at_least[0] bricks that are not constant may still fit one
    atlas and the cap (level_bytes' least: those bricks' slots, the page table, one constant)."""
    count = at_least[0]
    try:
        slot_grid(count, store.brick, max_side)
    except ValueError:
        return False
    least = count * slot_bytes(store.brick, channels, exact_uint8) + _table_bytes(store, 1)
    return least <= cap


@dataclasses.dataclass
class Placement:
    """Where a volume goes, decided on the host (no GL calls: app/rendering/levels/progressive_open.py
    decides on a thread): `shown` the volume shown (a coarser level under a cap, or a mix of two
    levels, with its note), `plan` its pool where it is bricked (None: one texture)."""
    shown: Volume
    plan: PoolPlan | None


def device_limits(ctx: moderngl.Context) -> tuple[int, int | None, str]:
    """(GL_MAX_3D_TEXTURE_SIZE, the bytes the device has left or None, what they are): what
    plan_placement needs from the context."""
    available, where = device_available(ctx)
    return int(ctx.info["GL_MAX_3D_TEXTURE_SIZE"]), available, where


def plan_placement(volume: Volume, limits, memory_bytes: int | None = None,
                   brick_size: int | None = None, camera=None) -> Placement:
    """Where `volume` goes under `limits` (device_limits): one texture where it fits, else the
    finest level whose bricks that are not constant fit the cap, and with a `camera` the memory
    it leaves filled with the next finer level's bricks the camera sees largest
    (app/rendering/levels/level_mix.py). Reads the range passes it needs; no GL calls."""
    max_side, available, where = limits
    channels = volume.channel_count
    exact = volume.exact_uint8
    whole = int(np.prod(volume.dims, dtype=np.int64)) * texel_bytes(channels, exact)
    in_memory = isinstance(volume.data, np.ndarray)
    if (in_memory and brick_size is None and max(volume.dims) <= max_side
            and (memory_bytes is None or whole <= memory_bytes)
            and (available is None or whole <= available)):
        return Placement(volume, None)
    brick = int(brick_size or DEFAULT_BRICK_SIZE)
    cap, cap_name = memory_bytes, "volume_memory_bytes"
    if cap is None and available is not None:
        cap, cap_name = available, where
    if cap is not None:
        refuse_cap_below_brick(cap, brick, channels, exact, volume.name)
    current, level, over_cap = volume, 0, None
    finer = None                       # (the level one finer, its store)
    bounds: dict = {}                  # the bound's coarse levels read, by source
    while True:
        store = _store(current, brick)
        at_least = None
        if cap is not None and not store.ranges_read:
            at_least = _resident_at_least(current, store, bounds)
        if at_least is not None and not _may_fit(at_least, store, channels, current.exact_uint8,
                                                 max_side, cap):
            need = None                # over the cap: its range pass is not read
            if over_cap is None:
                count, source = at_least
                nx, ny, nz = source.shape[:3][::-1]
                over_cap = (f"level 0 has at least {count} bricks that are not constant (seen "
                            f"in its {nx} x {ny} x {nz} level), over the {_gib(cap)} cap "
                            f"({cap_name})")
        else:
            need = level_bytes(store, channels, current.exact_uint8, max_side)
            if over_cap is None:
                first = store.resident_count()
                over_cap = (f"level 0's {first} bricks exceed one atlas texture of "
                            f"{max_side}^3 texels" if need is None else
                            f"level 0's {first} bricks take {_gib(need)}, over the "
                            f"{_gib(cap)} cap ({cap_name})")
            if need is not None and (cap is None or need <= cap):
                break
        if max(current.dims) <= brick:
            raise VolumeError(f"{volume.name}: even one brick of {brick}^3 voxels exceeds the "
                              f"{_gib(cap)} of {cap_name}")
        finer = (current, store)
        current, level = coarser(current, brick), level + 1
    notes = current.notes
    # mixed only under a cap given (filling the device's whole free memory would leave none for
    # the probes and images)
    if level > 0 and memory_bytes is not None and camera is not None:
        fine_volume, fine_store = finer
        plan, why = mixed_plan(fine_store, store, cap, camera, current.half_extent, max_side,
                               exact, volume.name)
        if plan is not None:
            f, c = fine_volume.dims, current.dims
            cells = macrocell_counts(f)
            ranges = mixed_density_ranges(fine_store, store, plan.level_of_brick, cells)
            note = (f"levels {level - 1} and {level} mixed ({f[0]} x {f[1]} x {f[2]} where the "
                    f"camera sees its voxels largest, {c[0]} x {c[1]} x {c[2]} elsewhere) under the "
                    f"{_gib(cap)} cap ({cap_name}): {why}")
            shown = dataclasses.replace(fine_volume, bricks=fine_store,
                                        notes=fine_volume.notes + (note,), derived={})
            shown.derived[("density ranges", cells)] = ranges
            return Placement(shown, plan)
    if level > 0:
        nx, ny, nz = current.dims
        notes += (f"level {level}, {2 ** level}x coarser ({nx} x {ny} x {nz}): {over_cap}",)
    return Placement(dataclasses.replace(current, bricks=store, notes=notes),
                     store.pool_plan(max_side))


def place_volume(ctx: moderngl.Context, volume: Volume, memory_bytes: int | None = None,
                 brick_size: int | None = None, camera=None):
    """(the volume shown, its texture or BrickPool). `memory_bytes`: the cap on the volume's GPU
    memory (None: the device's memory left); `brick_size`: bricks of that many voxels, forced
    (None: bricked only where one texture does not fit, in bricks of 64); `camera`: under a cap,
    levels mixed by what it sees (plan_placement; None: one whole level)."""
    placement = plan_placement(volume, device_limits(ctx), memory_bytes, brick_size, camera)
    if placement.plan is None:
        return placement.shown, volume_texture(ctx, placement.shown)
    return placement.shown, upload_plan(ctx, placement.plan, placement.shown.exact_uint8)
