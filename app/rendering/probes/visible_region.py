"""The visible region on the GPU (glsl/visible_region.comp; NumPy twin app/twins/visible_region.py):
one pass over the volume's cells and a 24-byte read-back, redone when the volume, the transfer
function or the density scale's sign changes. NumPy took 1.3 s on bonsai (256^3) on two CPU cores
for every transfer-function edit, which the viewer felt as a stall."""
from __future__ import annotations

import moderngl
import numpy as np

from radiance_probes.scene.channels import channel_uniforms
from radiance_probes.scene.clip_region import region_uniforms
from radiance_probes.gl.shaders import ComputeProgram, compute_program, set_uniforms
from radiance_probes.twins.visible_region import positive_node_counts, region_from_cells
from radiance_probes.rendering.resources import TRANSFER_UNIT, VOLUME_UNIT, SceneResources

COUNTS_UNIT = 15   # the positive-node counts, read only during the pass (14: the adaptive layout's warp)
NONE_VISIBLE = 0xFFFFFFFF

class VisibleRegionPass:
    """The pass and its program, owned by one Renderer (compiled on first use, released with it)."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.program: ComputeProgram | None = None
        self.defines = None   # the medium's defines the program was built with

    def region(self, resources: SceneResources) -> tuple[np.ndarray, np.ndarray]:
        """World (low, high) corners of where sigma_t can be > 0 (the whole box, or the kept box
        of a crop or clip plane, when nowhere)."""
        ctx = self.ctx
        half = np.asarray(resources.volume.half_extent, np.float64)
        clip = resources.clip
        whole = ((-half, half) if clip is None else
                 (np.asarray(clip.box_min, np.float64), np.asarray(clip.box_max, np.float64)))
        if resources.scene.density_scale <= 0 or (clip is not None and clip.empty):
            return whole
        tables = resources.tables
        channels = 1 if tables is None else tables.count
        defines = resources.medium_defines()
        if self.program is None or self.defines != defines:
            if self.program is not None:
                self.program.release()
            self.program = compute_program(ctx, "visible_region.comp", defines)
            self.defines = defines
        program = self.program
        dims = tuple(int(v) for v in resources.volume.dims)
        if tables is None:
            counts = positive_node_counts(resources.table[:, 3])[None]
        else:
            counts = np.stack([positive_node_counts(t[:, 3]) for t in tables.padded()])
            set_uniforms(program, channel_uniforms(tables))
        counts = np.ascontiguousarray(counts, np.int32)
        counts_tex = ctx.texture((counts.shape[1], counts.shape[0]), 1, counts.tobytes(),
                                 dtype="i4")
        counts_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        cells = ctx.buffer(np.array([NONE_VISIBLE] * 3 + [0] * 3, np.uint32).tobytes())
        try:
            resources.bind()
            counts_tex.use(COUNTS_UNIT)
            first = (0, 0, 0) if clip is None else clip.voxel_first
            count = dims if clip is None else clip.voxel_count
            set_uniforms(program, {"volume_density": VOLUME_UNIT, "transfer_function": TRANSFER_UNIT,
                                   "transfer_size": int(resources.transfer_size),
                                   "positive_node_counts": COUNTS_UNIT, "dims": dims,
                                   "voxel_first": tuple(first), "voxel_count": tuple(count),
                                   "box_half_extent": tuple(float(v) for v in half),
                                   **region_uniforms(clip),
                                   **(resources.volume_tex.uniforms() if resources.bricked
                                      else {})})
            cells.bind_to_storage_buffer(0)
            program.run((count[0] + 8) // 8, (count[1] + 8) // 8, (count[2] + 4) // 4)
            ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT)
            found = np.frombuffer(cells.read(), np.uint32)
        finally:
            counts_tex.release()
            cells.release()
        if found[0] == NONE_VISIBLE:
            return whole
        return region_from_cells(found[:3], found[3:], dims, half, clip)

    def release(self) -> None:
        if self.program is not None:
            self.program.release()
            self.program = None
