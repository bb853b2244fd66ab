"""The sun's transmittance baked on a grid sheared along the sun's direction
(glsl/light_transmittance.comp, layout in light_grid_layout.py), which the raymarcher and the
bake's walks read instead of tracing a shadow ray."""
from __future__ import annotations

import moderngl
import numpy as np

from radiance_probes.gl.shaders import compute_program, set_uniforms
from radiance_probes.scene.light_grid_layout import LightGridLayout, light_grid_layout
from radiance_probes.rendering.resources import SceneResources

LIGHT_UNIT = 9
RAYS_PER_GROUP = (32, 2)   # light_transmittance.comp's local size (rays along b, c)
LIGHT_MARCH_VOXELS = 2.0   # march step in half voxels (resources.march_step)
MIN_SIDE = 128  # texels along the volume's longest axis at least (small volumes are upsampled)
MAX_SIDE = 512  # texels per axis at most; the volume's own resolution up to that
# Texels per probe spacing at least, along the longest axis: the sun's transmittance from the grid
# is the raymarcher's direct light and the walks' sun, and its interpolation error must stay below
# the probes' own. Measured on the H100 (bench/h100-light-sheared, 64 walks, raymarch rRMSE with
# 256 / 384 / 512 texels): 32^3 probes, bonsai 8.65 / 8.36 / 8.26% (foot 3.63 / 3.45 / 3.37%);
# 64^3, 5.11 / 4.80 / 4.69% (foot 2.35 / 2.10 / 2.01%); 128^3, 2.69 / 2.34 / 2.23% (foot 1.54 /
# 1.21 / 1.10%), for 0.9 / 2.9 / 6.6 ms of grid. Hence 12 texels per probe spacing: 384 at 32^3,
# the 512 cap from 43^3 up.
TEXELS_PER_PROBE = 12
# ... but at most this many texels per voxel along the longest axis (or MIN_SIDE): the grid has to
# resolve the density's own shadow edges, not the probes'. Measured on the H100 (bench/h100
# against its version of commit 6db535c): fuel's 64^3 volume with 128 texels, instead of the 384
# to 512 that 12 per probe spacing asks for, reaches 5% 74x sooner than the path tracer instead
# of 15x and 2% 207x instead of 70x, but 1% later (84.6 against 10.5 ms).
VOLUME_UPSAMPLING = 2


def light_grid_size(dims: tuple[int, int, int], max_side: int = MAX_SIDE,
                    min_side: int = MIN_SIDE) -> tuple[int, int, int]:
    """Texels per axis: the volume's resolution, upsampled so that the longest axis has at least
    min_side (the sun's transmittance varies inside a voxel: on fuel, 64^3, the RMS error of the
    sun at scattering points falls from 6.8% at 64^3 to 1.6% at 128^3) but no more than
    VOLUME_UPSAMPLING times the volume's (or MIN_SIDE), at most max_side per axis."""
    longest = max(dims)
    side = min(min_side, max(MIN_SIDE, VOLUME_UPSAMPLING * longest))
    scale = max(1.0, side / longest)
    return tuple(int(min(max(1, round(d * scale)), max_side)) for d in dims)


def min_side_for_probes(probe_grid: tuple[int, int, int] | None, floor: int = MIN_SIDE) -> int:
    """The light grid's least texels along the longest axis for a probe grid (None: no probes),
    and at least `floor`."""
    return max(floor, TEXELS_PER_PROBE * max(probe_grid)) if probe_grid else floor


# Residual-tracked shadow rays (lib/sun_shadow.glsl): the control's lattice spacing along the ray,
# in the grid's largest texel sides (one grid read a node).
SHADOW_CONTROL_TEXELS = 1.0


# On a CPU rasterizer the light grid keeps the volume's own resolution: upsampling a 24^3 test
# volume's grid to 128^3 took 0.9 s per bake on llvmpipe's two cores against 12 ms, and every
# light, transfer-function or probe edit re-bakes it.
SOFTWARE_MIN_SIDE = 1


# The texture's precision: 16-bit floats hold the optical depth to 1 part in 2048 (the
# transmittance to tau / 2048 relative: 0.15% at tau = 3), far below the grid's interpolation error,
# in half the memory of 32-bit ones. Measured on the H100 (bench/h100-light-sheared): the same
# raymarched rRMSE within 0.01 points at every probe grid and size on bonsai and the foot; 742 MB
# against 1.48 GB at 512 texels under the bench's sun, and the faster bake since the march's
# neighbouring invocations write neighbouring texels (1.33 against 1.84 ms; bench/h100-light-sheared
# time_coalesced.json: before that, 6.6 against 3.3 ms).
PRECISIONS = {"f2": "r16f", "f4": "r32f"}
PRECISION = "f2"

# Columns cut into segments (light_transmittance.comp) for about this many invocations (an H100's
# resident threads: 132 SMs x 2048), where that takes MIN_SEGMENTS or more: a small grid's few
# columns leave a large GPU waiting for each column's chain of fetches. Measured on the H100
# (bench/h100-small, bench/h100): 29 to 38 thousand columns (the 8^3 probe grids' light grids)
# 0.081-0.091 -> 0.064-0.072 ms in 7 to 9 segments; 65 thousand in 4 0.12 -> 0.143 ms, 86 thousand
# in 4 0.145 -> 0.19 ms: there the GPU is already nearly full (the march runs at about the
# ceiling's rate of fetches) and the second pass only adds work (the foot's 146 thousand: 0.29 ->
# 0.48 ms in 2). 0 marches every column whole (a CPU rasterizer, where segments only add work).
SEGMENT_TARGET_INVOCATIONS = 1 << 18
MIN_SEGMENT_TEXELS = 8     # texels a segment marches at least
MIN_SEGMENTS = 5           # fewer were slower (2: 0.109 -> 0.116 ms on hydrogen's 8^3 grid)


def column_segments(layout: LightGridLayout, target: int = SEGMENT_TARGET_INVOCATIONS) -> int:
    """Segments per column for this layout: enough for `target` invocations over all columns, each
    at least MIN_SEGMENT_TEXELS long; 1 (whole columns) where that is fewer than MIN_SEGMENTS (or
    target 0)."""
    a = layout.axis
    b, c = layout.ray_axes
    rays = layout.size[b] * layout.size[c]
    if target <= 0:
        return 1
    segments = min(-(-target // rays), layout.size[a] // MIN_SEGMENT_TEXELS)
    return segments if segments >= MIN_SEGMENTS else 1


def covered_box(resources: SceneResources) -> tuple[tuple[int, int, int], np.ndarray, np.ndarray]:
    """The box the light grid covers, as (voxels per axis, half extent, centre): the volume's, or
    with a crop or clip plane the kept box and the voxels the crop keeps (the grid a cropped
    volume of those voxels would get, at the same place)."""
    clip, volume = resources.clip, resources.volume
    if clip is None or clip.empty:
        return (tuple(volume.dims), np.asarray(volume.half_extent, np.float64), np.zeros(3))
    return tuple(clip.voxel_count), clip.half_extent, clip.centre


class LightTransmittance:
    def __init__(self, ctx: moderngl.Context, max_side: int = MAX_SIDE, precision: str = PRECISION,
                 segment_target: int = SEGMENT_TARGET_INVOCATIONS, medium: dict | None = None):
        """`medium`: the scene's medium defines (SceneResources.medium_defines: its channels)."""
        self.ctx = ctx
        self.medium = dict(medium or {})
        self.max_side = int(max_side)
        self.precision = precision
        self.segment_target = int(segment_target)   # column_segments; 0: whole columns
        self._segment_depths: moderngl.Buffer | None = None   # [ray][segment] optical depths
        self.segments = 1        # per column in the last bake_layers
        self.march_step = 1.0    # the bake's quadrature step (world units), set by begin()
        self.program = compute_program(ctx, "light_transmittance.comp",
                                       {"LIGHT_GRID_FORMAT": PRECISIONS[precision], **self.medium})
        self._segment_program = None   # the LIGHT_GRID_SEGMENTS build, compiled when first used
        self.texture: moderngl.Texture3D | None = None   # what readers use
        self.layout: LightGridLayout | None = None       # of the texture's contents
        # A bake in a new layout goes to its own texture, which replaces the readers' when done.
        self._target: moderngl.Texture3D | None = None
        self.target_layout: LightGridLayout | None = None   # of the bake under way
        self.box_grid = (0, 0, 0)     # texels per axis over the box (light_grid_size)
        self.next_layer = 0

    @property
    def baking_layout(self) -> LightGridLayout | None:
        """The layout of the bake under way, or of the last one."""
        return self.target_layout or self.layout

    @property
    def grid(self) -> tuple[int, int, int]:
        """Texels per axis (x, y, z) of the grid being baked (or last baked)."""
        layout = self.baking_layout
        return layout.size if layout is not None else (0, 0, 0)

    @property
    def layers(self) -> int:
        """Slabs a sliced bake takes at most: ray rows along the layout's layer axis."""
        layout = self.baking_layout
        return layout.size[layout.layer_axis] if layout is not None else 0

    def _texture(self, size: tuple[int, int, int]) -> moderngl.Texture3D:
        texture = self.ctx.texture3d(size, 1, dtype=self.precision)
        texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
        texture.repeat_x = texture.repeat_y = texture.repeat_z = False
        return texture

    def begin(self, resources: SceneResources, sun_direction, min_side: int = MIN_SIDE) -> None:
        """Starts a bake that bake_layers() does a slab of rays at a time (the viewer's budgeted
        frames). In the same layout it overwrites the texture in place: until it is done the
        texture holds the new rays below next_layer and the previous grid's above, which readers
        may use as they are (each ray is marched on its own). A new layout (the sun moved, or
        another size) is baked into a texture of its own while readers keep the previous grid
        whole, and replaces it when done."""
        dims, half, centre = covered_box(resources)
        self.box_grid = light_grid_size(dims, self.max_side, min_side)
        self.march_step = LIGHT_MARCH_VOXELS * resources.march_step
        layout = light_grid_layout(self.box_grid, half, sun_direction, self.max_side, centre)
        if self.texture is None or layout == self.layout:
            if self.texture is None:
                self.texture = self._texture(layout.size)
            self.layout = layout
            self._drop_target()
        else:
            if self._target is None or self._target.size != layout.size:
                self._drop_target()
                self._target = self._texture(layout.size)
            self.target_layout = layout
        self.next_layer = 0

    def _drop_target(self) -> None:
        if self._target is not None:
            self._target.release()
        self._target, self.target_layout = None, None

    @property
    def done(self) -> bool:
        return (self.texture is not None and self.target_layout is None
                and self.next_layer >= self.layers)

    def bake_layers(self, resources: SceneResources, layers: int | None = None) -> int:
        """Bakes the next `layers` slabs of rays (None: all that are left); returns how many ran.
        The last slab of a bake in a new layout hands its texture to the readers."""
        first = self.next_layer
        left = self.layers - first
        count = left if layers is None else max(0, min(int(layers), left))
        if count == 0:
            return 0
        layout = self.baking_layout
        texture = self._target if self.target_layout is not None else self.texture
        grid = layout.size
        segments = column_segments(layout, self.segment_target)
        self.segments = segments
        if segments > 1 and self._segment_program is None:
            self._segment_program = compute_program(
                self.ctx, "light_transmittance.comp",
                {"LIGHT_GRID_FORMAT": PRECISIONS[self.precision], "LIGHT_GRID_SEGMENTS": 1,
                 **self.medium})
        program = self.program if segments == 1 else self._segment_program
        resources.bind()
        set_uniforms(program, resources.uniforms())
        set_uniforms(program, layout.uniforms())
        # Quadrature every voxel (the probes' march takes half voxels): the grid's own interpolation
        # error dominates; measured on bonsai at 256^3, RMS error of the sun's transmittance at
        # scattering points 7.6% against 7.4%, for half the time.
        set_uniforms(program, {"grid": grid, "first_layer": first,
                               "march_step": LIGHT_MARCH_VOXELS * resources.march_step})
        texture.bind_to_image(0, read=False, write=True)
        rows = grid[layout.ray_axes[0]]
        groups = ((rows + RAYS_PER_GROUP[0] - 1) // RAYS_PER_GROUP[0],
                  (count + RAYS_PER_GROUP[1] - 1) // RAYS_PER_GROUP[1])
        if segments == 1:
            program.run(*groups, 1)
        else:
            need = 4 * segments * rows * grid[layout.ray_axes[1]]
            if self._segment_depths is None or self._segment_depths.size < need:
                if self._segment_depths is not None:
                    self._segment_depths.release()
                self._segment_depths = self.ctx.buffer(reserve=need)
            self._segment_depths.bind_to_storage_buffer(0)
            for segment_pass in (0, 1):
                set_uniforms(program, {"segments": segments, "segment_pass": segment_pass})
                program.run(*groups, segments)
                if segment_pass == 0:
                    self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
        self.ctx.memory_barrier(moderngl.TEXTURE_FETCH_BARRIER_BIT)
        self.next_layer = first + count
        if self.target_layout is not None and self.next_layer >= self.layers:
            self.texture.release()
            self.texture, self.layout = self._target, self.target_layout
            self._target, self.target_layout = None, None
        return count

    def uniforms(self) -> dict:
        """What a reader of the grid (lib/light_grid.glsl) needs besides the texture unit."""
        # lib/light_grid.glsl marches the last texel before the box's sun side itself
        texel = float(np.max(2.0 * np.asarray(self.layout.half_extent) / np.asarray(self.layout.size)))
        return {"light_transmittance": LIGHT_UNIT, **self.layout.uniforms(),
                "light_grid_texel": texel, "light_grid_march_step": self.march_step,
                "shadow_control_step": SHADOW_CONTROL_TEXELS * texel}

    def read(self) -> np.ndarray:
        """The optical depth (z, y, x) of the texture, in the layout's sheared coordinates."""
        w, h, d = self.texture.size
        dtype = np.float16 if self.precision == "f2" else np.float32
        return np.frombuffer(self.texture.read(), dtype).reshape(d, h, w).astype(np.float32)

    @property
    def gpu_bytes(self) -> int:
        return (sum(int(self.precision[1]) * t.width * t.height * t.depth
                    for t in (self.texture, self._target) if t is not None)
                + (self._segment_depths.size if self._segment_depths is not None else 0))

    def bind(self) -> None:
        self.texture.use(LIGHT_UNIT)

    def release(self) -> None:
        self.program.release()
        if self._segment_program is not None:
            self._segment_program.release()
        self._drop_target()
        if self._segment_depths is not None:
            self._segment_depths.release()
        if self.texture is not None:
            self.texture.release()
