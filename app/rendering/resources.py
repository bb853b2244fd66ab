"""The scene on the GPU: volume and transfer function textures, the uniforms every pass shares,
and the tracking statistics buffer. Re-uploads only what a scene change touches."""
from __future__ import annotations

import math
import struct
from collections import OrderedDict

import moderngl
import numpy as np

from radiance_probes.scene.area_lights import area_light_uniforms, check_area_lights
from radiance_probes.scene.channels import (ChannelTables, channel_uniforms, effective_channels,
                                            volume_inputs)
from radiance_probes.scene.clip_region import ClipRegion, clip_region, region_uniforms
from radiance_probes.io.environment_map import EnvironmentMap, load_scene_environment
from radiance_probes.gl.brick_pool import BrickPool
from radiance_probes.gl.textures import TransferTable
from radiance_probes.io.environment_map import Distribution
from radiance_probes.twins.medium import majorant
from radiance_probes.io.scene_file import Scene
from radiance_probes.scene.transfer import transfer_table
from radiance_probes.io.volume import Volume
from radiance_probes.io.load import load_scene_volume
from radiance_probes.twins.majorant_grid import macrocell_counts
from radiance_probes.rendering.cache_keys import KEYS, majorant_grid_key, scene_key
from radiance_probes.rendering.grids.majorant_grid import MAJORANT_UNIT, MajorantGrid
from radiance_probes.rendering.levels.volume_placement import place_volume

VOLUME_UNIT = 0
TRANSFER_UNIT = 1
ENVIRONMENT_MAP_UNIT = 12   # lib/environment_map.glsl: radiance and pdf (RGBA32F)
ENVIRONMENT_CDF_UNIT = 13   # and its CDFs (R32F)
STATS_BINDING = 7
# Tracking steps (null and real collisions, shadow-ray steps) one path may take before it is
# dropped and counted as truncated. Far beyond what max_bounces = 64 needs even at sigma_t = 1e4;
# it only stops a pathological scene from hanging the GPU.
DEFAULT_MAX_PATH_STEPS = 1 << 24
# A time series' steps kept for showing again (host data and GPU texture together).
STEP_CACHE_BYTES = 1 << 30


def environment_textures(ctx: moderngl.Context, image: np.ndarray, distribution: Distribution):
    """The two textures lib/environment_map.glsl reads: RGBA32F (rgb radiance, a the density over
    (u, v)) and the R32F CDFs (app/twins/environment_map.py); texelFetch only."""
    h, w = image.shape[:2]
    rgba = np.empty((h, w, 4), np.float32)
    rgba[..., :3] = image
    rgba[..., 3] = distribution.pdf_uv
    tex = ctx.texture((w, h), 4, rgba.tobytes(), dtype="f4")
    cdf = distribution.cdf_texture()
    cdf_tex = ctx.texture((w + 1, h + 1), 1, cdf.tobytes(), dtype="f4")
    for t in (tex, cdf_tex):
        t.filter = (moderngl.NEAREST, moderngl.NEAREST)
    return tex, cdf_tex


class SceneResources:
    def __init__(self, ctx: moderngl.Context, scene: Scene, volume: Volume | None = None,
                 use_majorant_grid: bool = True, volume_memory_bytes: int | None = None,
                 brick_size: int | None = None, mixed_levels: bool = False):
        self.ctx = ctx
        self.scene: Scene | None = None
        self.volume: Volume | None = None
        self.volume_tex = None
        self.transfer_gpu = None
        self.table: np.ndarray | None = None   # one channel's (of several: channel 0's)
        self.tables: ChannelTables | None = None   # several channels: all of them
        self.environment: EnvironmentMap | None = None   # the scene's map, None: constant
        self.environment_tex = None
        self.environment_cdf_tex = None
        # False: paths find the map by phase sampling alone (LabOptions.environment_sampling).
        self.environment_sampling = True
        self.stats = ctx.buffer(reserve=16)
        self.max_path_steps = DEFAULT_MAX_PATH_STEPS
        # Counts volume changes; keys of what was computed from a volume use it, not id(volume):
        # a freed volume's id can be reused by the next one, and baked data would look current.
        self.volume_version = 0
        # Empty-space skipping: tracking walks a grid of per-macrocell majorants (rebuilt on the
        # GPU when the transfer function, density_scale or volume changes; never for the camera).
        # False: the single global majorant everywhere (the same estimator, for comparison).
        self.use_majorant_grid = bool(use_majorant_grid)
        self.majorant_grid = MajorantGrid(ctx)
        self._majorant_key: tuple | None = None
        # The crop box and clip plane resolved against the volume (app/scene/clip_region.py); None: the
        # whole volume is kept.
        self.clip: ClipRegion | None = None
        # A time series' steps shown, kept (volume and texture) up to this many bytes in all:
        # stepping back and forth, or playing the series again, uploads nothing.
        self.step_cache_bytes = STEP_CACHE_BYTES
        self._steps: OrderedDict = OrderedDict()
        # Bricking (app/rendering/levels/volume_placement.py): the cap on the volume's GPU memory (None:
        # what the device has left) and a forced brick size (None: bricks of 64 voxels where one
        # texture does not fit). The volume given or loaded is kept (`given`) to place again
        # when they change.
        self.volume_memory_bytes = volume_memory_bytes
        self.brick_size = brick_size
        self.mixed_levels = bool(mixed_levels)   # levels mixed by the camera under the cap
        self.given_volume: Volume | None = None
        self.update(scene, volume)

    def update(self, scene: Scene, volume: Volume | None = None, placed=None) -> set[str]:
        """Adopt a new scene; returns which parts changed ('volume', 'transfer', 'medium', ...).
        `placed`: (the volume shown, its texture or BrickPool) of `volume`, already placed
        (app/rendering/levels/progressive_open.py); else place_volume places it here."""
        changed: set[str] = set()
        old = self.scene
        # The map first: a bad file fails before anything on the GPU changes.
        old_map = None if old is None else (old.environment_map, old.base_dir)
        new_map = (scene.environment_map, scene.base_dir)
        environment = load_scene_environment(scene) if new_map != old_map else self.environment
        inputs = volume_inputs(scene)
        kept_texture = None
        if volume is not None and volume is not self.volume and volume is not self.given_volume:
            changed.add("volume")
        elif old is None or inputs != volume_inputs(old):
            kept = self._steps.get(inputs)   # a time series' step shown before
            if kept is not None:
                volume, kept_texture = kept
                self._steps.move_to_end(inputs)
            else:
                volume = load_scene_volume(scene, self.brick_size)
            changed.add("volume")
        # A crop that does not fit the volume, or channels it lacks, fail before anything on the
        # GPU changes.
        if placed is not None and "volume" not in changed:
            raise ValueError("Resources.update: `placed` belongs with a new volume")
        if "volume" in changed and kept_texture is None:   # where it goes: a texture or bricks
            given = volume
            volume, kept_texture = (placed if placed is not None else
                                    place_volume(self.ctx, volume, self.volume_memory_bytes,
                                                 self.brick_size, self.placement_camera(scene)))
            self.given_volume = given
            fresh_texture = kept_texture
        else:
            fresh_texture = None
        new_volume = volume if "volume" in changed else self.volume
        try:
            clip = clip_region(scene, new_volume.dims, new_volume.half_extent)
            channels = effective_channels(scene, new_volume.channel_count)
            check_area_lights(scene, new_volume.half_extent)   # each light outside the box
        except BaseException:
            if fresh_texture is not None:
                fresh_texture.release()
            raise
        if "volume" in changed:
            if any(key[:-1] != inputs[:-1] for key in self._steps):   # another series, or none
                self._drop_steps()
            tex = kept_texture
            if self.volume_tex is not None and not self._step_kept(self.volume_tex):
                self.volume_tex.release()
            self.volume, self.volume_tex = volume, tex
            self.volume_version += 1
            if volume.time_steps > 1 and fresh_texture is not None:
                self._keep_step(inputs, volume, tex)
            self._trim_steps()
        if (old is None or "volume" in changed or scene.transfer_function != old.transfer_function
                or scene.channels != old.channels):
            if channels is None or len(channels) == 1:   # one channel: the classic medium
                self.tables = None
                self.table = transfer_table(scene.transfer_function if channels is None
                                            else channels[0].transfer_function)
            else:
                self.tables = ChannelTables.of(channels)
                self.table = self.tables.tables[0]
            if self.transfer_gpu is not None:
                self.transfer_gpu.release()
            self.transfer_gpu = TransferTable(self.ctx, self.medium_table)
            changed.add("transfer")
        if old is None or (scene.density_scale, scene.albedo, scene.anisotropy, scene.max_bounces,
                           scene.surface) != (old.density_scale, old.albedo, old.anisotropy,
                                              old.max_bounces, old.surface):
            changed.add("medium")
        if old is None or scene.light != old.light or scene.environment != old.environment or (
                scene.environment_map != old.environment_map) or (
                scene.area_lights != old.area_lights):
            changed.add("light")
        self._set_environment(environment)
        if old is None or scene.camera != old.camera:
            changed.add("camera")
        if clip != self.clip:
            changed.add("clip")
        self.clip = clip
        self.scene = scene
        if "volume" in changed:
            self.majorant_grid.set_volume(self.volume)
        key = (self.volume_version, clip, majorant_grid_key(scene))
        if key != self._majorant_key:
            self.majorant_grid.build(self.transfer_gpu, self.medium_table, scene.density_scale,
                                     TRANSFER_UNIT, clip=clip,
                                     half_extent=self.volume.half_extent)
            self._majorant_key = key
        return changed

    def _step_kept(self, texture) -> bool:
        return any(t is texture for _, t in self._steps.values())

    def _keep_step(self, key: tuple, volume: Volume, texture) -> None:
        """Keeps a time series' step (its volume and texture) for when it is shown again, the
        least recently shown dropped while the kept ones hold more than step_cache_bytes."""
        self._steps[key] = (volume, texture)
        self._steps.move_to_end(key)
        self._trim_steps()

    def _trim_steps(self) -> None:
        """Drops the least recently shown steps while the kept ones hold more than
        step_cache_bytes (never the one shown)."""
        def size(entry) -> int:
            v, t = entry
            gpu = t.nbytes if hasattr(t, "nbytes") else int(
                t.width * t.height * t.depth * t.components * (2 if v.exact_uint8 else 4))
            return int(v.data.nbytes) + gpu

        while len(self._steps) > 1 and sum(map(size, self._steps.values())) > self.step_cache_bytes:
            key, (v, t) = next(iter(self._steps.items()))
            if t is self.volume_tex:        # the one shown: keep it, drop the next oldest
                self._steps.move_to_end(key)
                continue
            del self._steps[key]
            t.release()

    @property
    def steps_kept(self) -> int:
        """How many steps of a time series are kept (host and GPU) for showing again."""
        return len(self._steps)

    def _set_environment(self, env: EnvironmentMap | None) -> None:
        """Uploads the map (radiance with its (u, v) density in alpha, and the CDFs) if it is new."""
        if env is self.environment:
            return
        for tex in (self.environment_tex, self.environment_cdf_tex):
            if tex is not None:
                tex.release()
        self.environment, self.environment_tex, self.environment_cdf_tex = env, None, None
        if env is None:
            return
        self.environment_tex, self.environment_cdf_tex = environment_textures(
            self.ctx, env.image, env.distribution)

    def defines(self) -> dict:
        """Compile-time variants of the scene: its medium's channels (MEDIUM_CHANNELS, in every
        pass that includes lib/medium.glsl; medium_defines) and what its lights need in every
        pass that includes lib/lights.glsl; and PHASE_ISOTROPIC with surfaces where g = 0, for the
        passes that read the probes (lib/probes.glsl: the phase function's light from band 0
        alone; surfaces make the probes order 2, which g = 0 does not need, where k = 0 keeps
        order 0 and the sum folds away by itself)."""
        defines = self.medium_defines()
        if "HYBRID_SCATTERING" in defines and self.scene.anisotropy == 0.0:
            defines = {**defines, "PHASE_ISOTROPIC": 1}
        if self.area_lights_on:
            defines = {**defines, "AREA_LIGHTS": 1}   # lib/area_lights.glsl
        if self.environment is None:
            return defines
        return {**defines, "ENVIRONMENT_MAP": 1} if self.environment_sampling else {
            **defines, "ENVIRONMENT_MAP": 1, "ENVIRONMENT_MAP_SAMPLING": 0}

    def medium_defines(self) -> dict:
        """What every pass that includes lib/medium.glsl is compiled with for this scene: nothing
        for one channel (the one-channel code, unchanged), else MEDIUM_CHANNELS; NO_CLIP_REGION
        where no crop or clip plane is set; and HYBRID_SCATTERING where the scene's
        surface.gradient_factor is above 0. A pass built with them is rebuilt when they change."""
        defines = {} if self.tables is None else {"MEDIUM_CHANNELS": self.tables.count}
        if self.clip is None:
            # no crop or clip plane: lib/clip_region.glsl's tests fold away (a uniform test cost
            # the walks 7%); a crop set later changes these defines, so every pass is rebuilt
            defines = {**defines, "NO_CLIP_REGION": 1}
        if self.scene.surface.gradient_factor > 0.0:
            # hybrid scattering (glsl/lib/hybrid_scattering.glsl: the medium scatters by a
            # surface BRDF too); k = 0 compiles every pass without it, as it was
            defines = {**defines, "HYBRID_SCATTERING": 1}
        return {**defines, **self.volume_tex.defines()} if self.bricked else defines

    @property
    def bricked(self) -> bool:
        """Whether the volume is read through a brick pool (lib/brick_pool.glsl)."""
        return isinstance(self.volume_tex, BrickPool)

    @property
    def stream(self):
        """The mixed pool's LevelStream (app/rendering/levels/level_stream.py; made on first use), None
        where the volume is not a streamed mix of levels."""
        pool = self.volume_tex
        if not isinstance(pool, BrickPool) or pool.plan is None:
            return None
        if pool.stream is None:
            from radiance_probes.rendering.levels.level_stream import LevelStream
            pool.stream = LevelStream(pool)
        return pool.stream

    def medium_restreamed(self) -> None:
        """A stream's commit changed the medium (which bricks read which level): the majorant
        grid's density ranges made for the new mix, and everything built from the volume made
        stale as for a new volume (volume_version: the majorant grid, the probes, the light
        grid, the visible region), without placing or uploading anything."""
        volume = self.volume
        cells = macrocell_counts(volume.dims)
        volume.derived[("density ranges", cells)] = self.stream.density_ranges(cells)
        self.volume_version += 1
        self.majorant_grid.set_volume(volume)
        s = self.scene
        self.majorant_grid.build(self.transfer_gpu, self.medium_table, s.density_scale,
                                 TRANSFER_UNIT, clip=self.clip, half_extent=volume.half_extent)
        self._majorant_key = (self.volume_version, self.clip, majorant_grid_key(s))

    def placement_camera(self, scene: Scene):
        """The camera levels are mixed for under a cap (place_volume), None: one whole level."""
        return scene.camera if self.mixed_levels else None

    def set_bricking(self, volume_memory_bytes: int | None, brick_size: int | None) -> None:
        """A new cap or brick size: the volume placed again (and everything built from it)."""
        if (volume_memory_bytes, brick_size) == (self.volume_memory_bytes, self.brick_size):
            return
        self.volume_memory_bytes, self.brick_size = volume_memory_bytes, brick_size
        given = self.given_volume
        if given is not None and not isinstance(given.data, np.ndarray) and brick_size is None:
            given = None   # read brick by brick for the old size: read again
        self._drop_steps()
        scene, self.scene = self.scene, None
        keep = self.volume_tex
        self.volume_tex = None
        if keep is not None:
            keep.release()
        self.volume, self.given_volume = None, None
        self._majorant_key = None
        self.update(scene, given)

    @property
    def medium_table(self):
        """The one-channel table, or the channels' tables (app.channels.ChannelTables): what the
        twins in app/twins take as the medium's `table`."""
        return self.table if self.tables is None else self.tables

    @property
    def transfer_size(self) -> int:
        """Rows of the (first channel's) transfer table: lib/medium.glsl transfer_size."""
        return int(len(self.table))

    @property
    def majorant(self) -> float:
        return majorant(self.medium_table, self.scene.density_scale)

    @property
    def march_step(self) -> float:
        """Half the smallest voxel side in world units: the deterministic marches' step. A
        streamed mix with no brick of the finer level in a slot yet reads the coarser level at
        every point, so it is marched at that level's half voxel (as the coarser level alone
        would be: the overview's frames of a mix cost what that level's do)."""
        he = self.volume.half_extent
        dims = self.volume.dims
        stream = self.stream
        if stream is not None and stream.resident == 0:
            dims = stream.coarse.dims
        return float(min(2.0 * he[i] / dims[i] for i in range(3)) / 2.0)

    def bake_key(self) -> tuple:
        """What the probes depend on in the scene (camera moves never re-bake): the volume's
        version, the crop resolved against it, and the Scene's fields the bake reads
        (cache_keys.py; Renderer.bake_key adds the settings')."""
        return (self.volume_version, self.clip,
                scene_key(self.scene, *KEYS["probe_bake"][0]))

    def uniforms(self) -> dict:
        s = self.scene
        return {
            "volume_density": VOLUME_UNIT,
            "transfer_function": TRANSFER_UNIT,
            "transfer_size": self.transfer_size,
            **({} if self.tables is None else channel_uniforms(self.tables)),
            "density_scale": float(s.density_scale),
            "albedo": float(s.albedo),
            "box_half_extent": tuple(float(v) for v in self.volume.half_extent),
            "majorant": self.majorant,
            "majorant_grid": MAJORANT_UNIT,
            "majorant_grid_bound": float(self.majorant_grid.bound),
            "use_majorant_grid": int(self.use_majorant_grid),
            "sun_direction": tuple(s.light.direction),
            "sun_irradiance": tuple(s.light.irradiance),
            "environment": tuple(s.environment),
            "max_bounces": int(s.max_bounces),
            "anisotropy": float(s.anisotropy),
            "max_path_steps": int(self.max_path_steps),
            **self.environment_uniforms(),
            **self.surface_uniforms(),
            **(area_light_uniforms(s) if self.area_lights_on else {}),
            **region_uniforms(self.clip),
            **(self.volume_tex.uniforms() if self.bricked else {}),
        }

    @property
    def area_lights_on(self) -> bool:
        """Whether the scene has an area light on (AREA_LIGHTS)."""
        return any(light.enabled for light in self.scene.area_lights)

    def surface_uniforms(self) -> dict:
        """glsl/lib/hybrid_scattering.glsl's uniforms (where k > 0; the passes without it have no
        such uniforms): k, roughness, F0 and the gradient's step, one voxel per axis."""
        surface = self.scene.surface
        if not surface.gradient_factor > 0.0:
            return {}
        he, dims = self.volume.half_extent, self.volume.dims
        return {"surface_gradient_factor": float(surface.gradient_factor),
                "surface_roughness": float(surface.roughness),
                "surface_specular": tuple(float(c) for c in surface.specular),
                "surface_gradient_step": tuple(float(2.0 * he[i] / dims[i]) for i in range(3))}

    def environment_uniforms(self) -> dict:
        if self.environment is None:
            return {}
        m = self.scene.environment_map
        h, w = self.environment.image.shape[:2]
        a = math.radians(m.rotation)
        return {"environment_map": ENVIRONMENT_MAP_UNIT, "environment_cdf": ENVIRONMENT_CDF_UNIT,
                "environment_size": (w, h), "environment_scale": float(m.scale),
                "environment_rotation": (math.cos(a), math.sin(a))}

    def bind(self) -> None:
        if self.bricked:
            self.volume_tex.use()
        else:
            self.volume_tex.use(VOLUME_UNIT)
        self.transfer_gpu.use(TRANSFER_UNIT)
        self.majorant_grid.bind()
        if self.environment_tex is not None:
            self.environment_tex.use(ENVIRONMENT_MAP_UNIT)
            self.environment_cdf_tex.use(ENVIRONMENT_CDF_UNIT)
        self.stats.bind_to_storage_buffer(STATS_BINDING)

    def reset_stats(self) -> None:
        self.stats.write(bytes(16))

    def read_stats(self) -> dict:
        truncated, nonfinite, _, _ = struct.unpack("4I", self.stats.read())
        return {"truncated_paths": truncated, "nonfinite_samples": nonfinite}

    def _drop_steps(self) -> None:
        """Forgets the kept steps (their textures released, but the one shown now)."""
        for _, t in self._steps.values():
            if t is not self.volume_tex:
                t.release()
        self._steps.clear()

    def release(self) -> None:
        self._drop_steps()
        for obj in (self.volume_tex, self.transfer_gpu, self.stats, self.environment_tex,
                    self.environment_cdf_tex):
            if obj is not None:
                obj.release()
        self.majorant_grid.release()
