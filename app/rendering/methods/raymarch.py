"""The raymarcher (glsl/lib/raymarch.glsl) as a compute pass or as the design card's fragment
pass; both are built from the same source and write the same accumulation image."""
from __future__ import annotations

import moderngl

from radiance_probes.twins.camera import CameraFrame
from radiance_probes.gl.shaders import compute_program, render_program, set_uniforms
from radiance_probes.rendering.methods.accumulation import Accumulation
from radiance_probes.rendering.methods.pathtracer import groups
from radiance_probes.rendering.budgets.sample_bands import TILE, tile_grid, tile_rects
from radiance_probes.rendering.resources import SceneResources

STAGES = ("compute", "fragment")
MAX_MARCH_STEPS = 8192   # glsl/lib/raymarch.glsl clamps a ray's step count to this
# The compute pass marches several frames in one dispatch (raymarch.comp with frame_layers > 0,
# then raymarch_resolve.comp) while the frames' pixels together stay within this many
# invocations: a 512x512 frame alone leaves a large GPU idle behind its slowest rays (H100:
# 0.68 ms a frame at 512^2 against 2.07 ms at 1920x1080, eight times the pixels), and an image
# this big fills it.
LAYER_PIXELS = 1 << 21
MAX_FRAME_LAYERS = 32   # layers of the frames' texture at most (tiny images)
# The compute pass's work groups (pixels across, down): 8 x 4, one warp, for the march without
# surfaces; 8 x 8 with them (HYBRID_SCATTERING) and for `guided`'s level 0 (GUIDED_LEVEL0).
# Measured on an H200 at 1920x1080 (bench/h200-hybrid-cost/workgroups*.json, every pixel's
# arithmetic the same, so the images are too): without surfaces the foot's frame 2.66 -> 2.28 ms
# and bonsai's 1.61 -> 1.33 ms at 8 x 4 (4 x 8 the same; 64 to 256 invocations 2.7 to 3.1 ms, 16
# 3.1 to 3.2 ms on the foot); with surfaces 8 x 4 was slower (foot 3.13 -> 3.33 ms, bonsai 1.73
# -> 1.89) and 16 x 8 within 2% of 8 x 8. Each side divides TILE: a band of 8 x 8 tiles
# (sample_bands) is whole groups.
GROUP_PLAIN = (8, 4)
GROUP_WIDE = (8, 8)


def group_shape(defines: dict | None) -> tuple[int, int]:
    """The compute pass's work-group shape for a build (`defines`): RAYMARCH_GROUP_X and _Y where
    the caller gives them, else GROUP_WIDE with surfaces or `guided`'s level 0, else GROUP_PLAIN."""
    defines = defines or {}
    if "RAYMARCH_GROUP_X" in defines:
        shape = (int(defines["RAYMARCH_GROUP_X"]), int(defines["RAYMARCH_GROUP_Y"]))
    elif "HYBRID_SCATTERING" in defines or "GUIDED_LEVEL0" in defines:
        shape = GROUP_WIDE
    else:
        shape = GROUP_PLAIN
    if any(side <= 0 or TILE % side for side in shape):
        raise ValueError(f"raymarch work group {shape}: each side must divide {TILE}")
    return shape


def frame_layers(width: int, height: int, frames: int = MAX_FRAME_LAYERS) -> int:
    """Frames one compute dispatch marches together: as many as keep the dispatch within
    LAYER_PIXELS invocations, at most `frames` and MAX_FRAME_LAYERS; 1 marches straight into the
    accumulation."""
    most = min(MAX_FRAME_LAYERS, LAYER_PIXELS // max(1, width * height))
    return max(1, min(frames, most))


def voxel_size(volume) -> float:
    """The smallest voxel side in world units (the box's longest side is 1)."""
    he = volume.half_extent
    return float(min(2.0 * he[i] / volume.dims[i] for i in range(3)))


def min_step_voxels(volume) -> float:
    """The smallest raymarch step (in voxels of the smallest side) the shader honours: a ray
    across the box's diagonal may take at most MAX_MARCH_STEPS steps, beyond which the shader
    would silently lengthen them."""
    diagonal = 2.0 * float((volume.half_extent.astype("float64") ** 2).sum() ** 0.5)
    return diagonal / MAX_MARCH_STEPS / voxel_size(volume)


def check_step(step_voxels: float, volume) -> None:
    """Raises ValueError for a step the shader would lengthen on this volume's longest rays."""
    low = min_step_voxels(volume)
    if step_voxels < low:
        raise ValueError(f"raymarch step {step_voxels:g} voxels: too fine for this volume (a ray "
                         f"across its box may take at most {MAX_MARCH_STEPS} steps); use at "
                         f"least {low:.3g}")


class Raymarcher:
    def __init__(self, ctx: moderngl.Context, stage: str = "compute", defines: dict | None = None):
        if stage not in STAGES:
            raise ValueError(f"raymarch stage must be one of {STAGES}, got {stage!r}")
        self.ctx = ctx
        self.stage = stage
        self._frame_values = None       # the layers one dispatch writes, one frame each
        if stage == "compute":
            self.group = group_shape(defines)
            self.program = compute_program(ctx, "raymarch.comp",
                                           {**(defines or {}), "RAYMARCH_GROUP_X": self.group[0],
                                            "RAYMARCH_GROUP_Y": self.group[1]})
            # folds layered frames into the accumulation (compiled with the march, so a new
            # variant costs its compiles at one moment)
            self._resolve = compute_program(ctx, "raymarch_resolve.comp")
        else:
            self.program = render_program(ctx, "fullscreen.vert", "raymarch.frag", defines)
            self.vao = ctx.vertex_array(self.program, [])
        self._fbo = None

    def _framebuffer(self, width: int, height: int):
        if self._fbo is None or self._fbo.size != (width, height):
            if self._fbo is not None:
                self._fbo.release()
            self._fbo = self.ctx.framebuffer(
                color_attachments=[self.ctx.renderbuffer((width, height), 1)])
        return self._fbo

    def _frame_values_for(self, width: int, height: int):
        # sized for the most frames a dispatch at this size may take, so that calls with fewer
        # frames (a progressive run's 1, 2, 4, ...) reuse it instead of allocating in a timed span
        size = (width, height, frame_layers(width, height))
        if self._frame_values is None or self._frame_values.size != size:
            if self._frame_values is not None:
                self._frame_values.release()
            self._frame_values = self.ctx.texture_array(size, 4, dtype="f4")
        return self._frame_values

    def run(self, resources: SceneResources, camera: CameraFrame, acc: Accumulation, frames: int,
            seed: int, step: float, uniforms: dict) -> None:
        """Adds `frames` jittered frames to acc's running mean: one dispatch per frame, or (compute,
        small images) several frames per dispatch folded in frame order, the same sums."""
        layers = frame_layers(acc.width, acc.height, frames) if self.stage == "compute" else 1
        resources.bind()
        set_uniforms(self.program, resources.uniforms())
        set_uniforms(self.program, camera.uniforms())
        set_uniforms(self.program, uniforms)
        set_uniforms(self.program, {"raymarch_step": step, "seed": seed & 0xFFFFFFFF,
                                    "frame_layers": 0,
                                    **({"tile_offset": (0, 0)} if self.stage == "compute"
                                       else {})})
        acc.bind_image(0)
        if layers > 1:
            self._frame_values_for(acc.width, acc.height).bind_to_image(1, read=True, write=True)
            set_uniforms(self._resolve, {"image_size": (acc.width, acc.height)})
            done = 0
            while done < frames:
                n = min(layers, frames - done)
                set_uniforms(self.program, {"frame_index": acc.samples, "frame_layers": n})
                self.program.run(*groups(acc.width, acc.height, self.group), n)
                self.ctx.memory_barrier(moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)
                set_uniforms(self._resolve, {"frame_index": acc.samples, "layers": n})
                self._resolve.run(*groups(acc.width, acc.height))
                self.ctx.memory_barrier(moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)
                acc.samples += n
                done += n
            return
        for _ in range(frames):
            set_uniforms(self.program, {"frame_index": acc.samples})
            if self.stage == "compute":
                self.program.run(*groups(acc.width, acc.height, self.group))
            else:
                fbo = self._framebuffer(acc.width, acc.height)
                fbo.use()
                self.vao.render(moderngl.TRIANGLES, vertices=3)
            self.ctx.memory_barrier(moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)
            acc.samples += 1

    def run_groups(self, resources: SceneResources, camera: CameraFrame, acc: Accumulation,
                   groups_range: tuple[int, int], seed: int, step: float,
                   uniforms: dict) -> None:
        """Marches work groups [first, end) in raster order (sample_bands.tile_rects: three
        rectangles at most) of frame acc.samples + 1 into acc's running mean (compute only: a
        pixel marched twice would count its frame twice, and a dispatch runs whole groups).
        acc.samples and acc.groups_done are the caller's to advance."""
        first, end = groups_range
        tiles_x, tiles_y = tile_grid(acc.width, acc.height)
        if self.stage != "compute":
            raise ValueError("the raymarcher marches bands of work groups as a compute pass only")
        if not 0 <= first < end <= tiles_x * tiles_y:
            raise ValueError(f"work groups {first}..{end} of {tiles_x * tiles_y}")
        resources.bind()
        set_uniforms(self.program, resources.uniforms())
        set_uniforms(self.program, camera.uniforms())
        set_uniforms(self.program, uniforms)
        set_uniforms(self.program, {"raymarch_step": step, "seed": seed & 0xFFFFFFFF,
                                    "frame_layers": 0, "frame_index": acc.samples})
        acc.bind_image(0)
        gx, gy = self.group
        for x0, y0, nx, ny in tile_rects(tiles_x, first, end):
            set_uniforms(self.program, {"tile_offset": (x0 * TILE, y0 * TILE)})
            self.program.run(nx * (TILE // gx), ny * (TILE // gy))
        self.ctx.memory_barrier(moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)

    def release(self) -> None:
        self.program.release()
        if self.stage == "compute":
            self._resolve.release()
        if self._frame_values is not None:
            self._frame_values.release()
        if self.stage == "fragment":
            self.vao.release()
        if self._fbo is not None:
            self._fbo.release()
