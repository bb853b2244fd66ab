"""The grids as the Renderer keeps them: the sun's light grid (the image's and the bake's own at a
coarser level), the opacity-gradient grid, the area lights' grid; each rebuilt when its cache key
changes, whole or in budgeted slices. A mixin of Renderer (app/rendering/renderer.py)."""
from __future__ import annotations

from dataclasses import dataclass

from radiance_probes.rendering.grids.area_light_grid import AreaLightGrid, area_light_grid_max_side
from radiance_probes.rendering.cache_keys import (area_light_grid_key, light_grid_key,
                                                  opacity_gradient_grid_key)
from radiance_probes.rendering.grids.light_transmittance import (LightTransmittance,
                                                                 min_side_for_probes)
from radiance_probes.rendering.grids.opacity_gradient_grid import OpacityGradientGrid
from radiance_probes.rendering.lab_options import LabOptions
from radiance_probes.rendering.probes.stage import _slice_estimate


# ... and of a sliced light-grid bake: this fraction of its slabs of sun rays (1/16).
FIRST_SLICE_LIGHT_FRACTION = 16


@dataclass
class _LightSlot:
    """A light grid and its bake's state: the image's (the raymarcher's sun, and the walks' at
    bake_level 0), or the bake's own at bake_level k > 0 (in the coarse medium)."""
    light: LightTransmittance | None = None
    key: tuple | None = None       # what the texture holds, once done
    pending: tuple | None = None   # the key of a sliced bake under way
    spent_ms: float = 0.0          # its GPU ms so far
    cost_ms: float = 0.0           # GPU ms the grid in hand took to bake

    def holds(self, key: tuple) -> bool:
        """Whether its texture holds the grid of `key`, done."""
        return self.light is not None and self.key == key


class GridStage:
    """The Renderer's cached grids: the light grids, the opacity-gradient grid, the area lights' grid."""

    @property
    def _light(self) -> LightTransmittance | None:
        """The light grid the image reads (the level shown)."""
        return self._image_light.light

    @property
    def light_cost_ms(self) -> float:
        """GPU ms the image's light grid in hand took to bake."""
        return self._image_light.cost_ms

    # ---- the raymarcher's opacity-gradient grid (opacity_gradient_grid.py) ---------------------
    def _gradient_grid_key(self) -> tuple:
        """What the grid depends on: the level shown's version, the crop resolved against it, the
        medium's fields (not density_scale) and its defines (channels, crop on or off)."""
        res = self.resources
        return (res.volume_version, res.clip, opacity_gradient_grid_key(self.scene),
                tuple(sorted(res.medium_defines().items())))

    def _gradient_grid_for_scene(self) -> OpacityGradientGrid | None:
        """The grid object where the raymarcher reads one (surfaces on, k > 0, and the lab's
        switch on; grid_refusal then says whether the grid can be made), None where it computes
        the gradient. With k = 0 a grid kept from before gives its memory back."""
        if not self.scene.surface.gradient_factor > 0.0:
            if self._gradient_grid is not None:
                self._gradient_grid.drop()
            return None
        if not self._lab.opacity_gradient_grid:
            return None
        if self._gradient_grid is None:
            self._gradient_grid = OpacityGradientGrid(self.ctx)
        return self._gradient_grid

    def bake_gradient_grid(self) -> float:
        """Bakes the raymarcher's opacity-gradient grid if stale (where it reads one); GPU ms (0
        where it was current, not read, or refused: opacity_gradient_grid.grid_refusal)."""
        self.last_gradient_grid_ms = 0.0
        grid = self._gradient_grid_for_scene()
        if grid is None:
            return 0.0
        key = self._gradient_grid_key()
        if grid.key == key:
            return 0.0
        self.timer.start()
        baked = grid.update(self.resources, key)
        self.timer.stop()
        if baked:
            self.last_gradient_grid_ms = grid.cost_ms = self.timer.elapsed_ms
        return self.last_gradient_grid_ms

    def _gradient_grid_ready(self) -> OpacityGradientGrid | None:
        """The grid the raymarcher reads now, made if stale (untimed: the callers that time it
        bake it first, bake_gradient_grid); None where the raymarcher computes the gradient."""
        grid = self._gradient_grid_for_scene()
        if grid is None:
            return None
        grid.update(self.resources, self._gradient_grid_key())
        return grid if grid.usable else None

    @property
    def opacity_gradient_grid(self) -> OpacityGradientGrid | None:
        """The raymarcher's opacity-gradient grid, None before one was needed (its texture,
        memory, and `refusal` where it could not be made)."""
        return self._gradient_grid

    def _light_target(self) -> tuple[tuple, int]:
        """The light grid the current scene needs: its key and least texels along the longest
        axis (it follows the probe grid: light_transmittance.TEXELS_PER_PROBE)."""
        s, st = self.scene, self._settings
        min_side = (min_side_for_probes(s.probes.grid, st.light_min_side)
                    if st.light_follows_probes else st.light_min_side)
        key = (self.resources.volume_version, self.resources.clip, min_side,
               light_grid_key(s, st))
        return key, min_side

    def light_current(self) -> bool:
        return self._image_light.holds(self._light_target()[0])

    def light_baking(self) -> bool:
        """Whether a sliced light-grid bake for the current scene is under way (bake_light with
        a budget): its texture then holds new layers and the previous grid's, and readers use it
        as it is rather than finish it in one go."""
        pending = self._image_light.pending
        return pending is not None and pending == self._light_target()[0]

    def bake_light(self, budget_ms: float | None = None) -> float:
        """Bakes the sun's transmittance grid for the raymarcher and the walks if stale; GPU ms.
        `budget_ms` None: all of it (or the rest of a sliced bake); otherwise slabs of sun rays
        that the GPU time per layer measured by earlier slabs of this grid size predicts fits
        (1/16 of the grid before any was timed; at least one layer). An edit in the middle of a
        sliced bake restarts it."""
        key, min_side = self._light_target()
        return self._bake_light_slot(self._image_light, self.resources, key, min_side, budget_ms)

    def _walk_light_target(self) -> tuple[tuple, int]:
        """The key and least side of the light grid the walks read: the image's at bake level 0,
        else its own in the coarse medium (the same settings, over the coarse level's voxels)."""
        key, min_side = self._light_target()
        level = self.bake_level()
        return ((key, level) if level else key), min_side

    def bake_walk_light(self, budget_ms: float | None = None) -> float:
        """The light grid the walks read (walk_sun "grid"), baked if stale as bake_light does:
        at bake level 0 the image's own, else the bake's in the coarse medium; GPU ms."""
        if self.bake_level() == 0:
            return self.bake_light(budget_ms)
        key, min_side = self._walk_light_target()
        return self._bake_light_slot(self._walk_light, self.bake_resources(), key, min_side,
                                     budget_ms)

    def walk_light(self) -> LightTransmittance | None:
        """The light grid the walks read (bake_walk_light's)."""
        return self._light if self.bake_level() == 0 else self._walk_light.light

    def walk_light_current(self) -> bool:
        if self.bake_level() == 0:
            return self.light_current()
        return self._walk_light.holds(self._walk_light_target()[0])

    def _bake_light_slot(self, slot: _LightSlot, resources, key: tuple, min_side: int,
                         budget_ms: float | None) -> float:
        """bake_light for one light grid (`slot`) over `resources`' medium."""
        st = self._settings
        medium = resources.medium_defines()
        if (slot.light is None or slot.light.max_side != st.light_max_side
                or slot.light.precision != st.light_precision or slot.light.medium != medium):
            if slot.light is not None:
                slot.light.release()
            slot.light = LightTransmittance(self.ctx, st.light_max_side, st.light_precision,
                                            medium=medium)
            # a new object holds no grid: its key may be the old one's (surfaces switched on or
            # off change the medium's defines, not the grid's key), which held a texture
            slot.key = slot.pending = None
        slot.light.segment_target = st.light_segment_target
        if key == slot.key:
            return 0.0
        light = slot.light
        if slot.pending != key:
            light.begin(resources, self.scene.light.direction, min_side)
            slot.key = None
            slot.pending = key
            slot.spent_ms = 0.0
        layers = None
        if budget_ms is not None:
            per_layer = self._layer_ms.get(light.grid)
            layers = (max(1, light.layers // FIRST_SLICE_LIGHT_FRACTION) if per_layer is None
                      else max(1, int(budget_ms / max(per_layer, 1e-9))))
        self.timer.start()
        ran = light.bake_layers(resources, layers)
        self.timer.stop()
        ms = self.timer.elapsed_ms
        if ran and layers is not None:
            seen = ms / ran
            per_layer = self._layer_ms.get(light.grid)
            self._layer_ms[light.grid] = _slice_estimate(per_layer, seen)
        slot.spent_ms += ms
        if light.done:
            slot.key, slot.pending = key, None
            slot.cost_ms = slot.spent_ms
        return ms

    def light_grid_ms(self) -> float:
        """What the light grid the current scene uses cost to bake (GPU ms), baking it if stale:
        also when an earlier call baked the same grid (the benchmark charges it to every image)."""
        self.bake_light()
        return self.light_cost_ms

    def forget_light_grid(self) -> None:
        """The next bake_light() bakes the image's light grid again (its time is then real)."""
        self._image_light.key = self._image_light.pending = None

    @property
    def light_grid(self) -> LightTransmittance | None:
        """The light grid the image reads (its size and memory are in the records)."""
        return self._light

    def _area_light_lab_defines(self, defines: dict | None) -> dict | None:
        """AREA_LIGHT_NEAR_POINTS where the lab asks for another count and a light is on."""
        points = self._lab.area_light_near_points
        if points == LabOptions().area_light_near_points or not self.resources.area_lights_on:
            return defines
        return {**(defines or {}), "AREA_LIGHT_NEAR_POINTS": points}

    def bake_area_light_grid(self) -> float:
        """Bakes the area lights' optical-depth grid (the raymarcher's and probes-only's direct
        light from them) if stale; GPU ms (0 where it was current or no light is on)."""
        if not self.resources.area_lights_on:
            return 0.0
        if self._area_grid is None:
            self._area_grid = AreaLightGrid(self.ctx, area_light_grid_max_side(self._software))
        res = self.resources
        key = (res.volume_version, res.clip, area_light_grid_key(self.scene),
               tuple(sorted(res.medium_defines().items())))
        if key == self._area_grid.key:
            return 0.0
        self._area_grid.compile(res)   # (not in the bake's time)
        self.timer.start()
        baked = self._area_grid.update(res, key)
        self.timer.stop()
        if not baked:
            return 0.0
        self._area_grid.cost_ms = self.timer.elapsed_ms
        return self._area_grid.cost_ms

    @property
    def area_light_grid(self) -> AreaLightGrid | None:
        """The area lights' grid, None before one was needed (its size, memory, builds)."""
        return self._area_grid
