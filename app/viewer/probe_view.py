"""The probe-grid view: probes as small spheres at their centres, shaded by the probe's SH
radiance at the sphere's normal under the current exposure (glsl/probe_sphere_instanced.vert and
probe_sphere.frag), instanced; and the volume box's outline.

Readable at any grid: only probes whose cell holds visible medium are drawn (what the transfer
function makes visible; all of them when nothing is), and on grids with more of those than
MAX_SPHERES every stride-th probe along each axis, the spheres growing with the stride, so a
32^3 grid over an unseen volume is a lattice through the visible part, not a wall."""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import moderngl
import numpy as np

from ..gl.shaders import render_program, set_uniforms
from ..rendering.probes import ProbeGrid
from ..rendering.resources import SceneResources
from ..twins.probe_warp import probe_fractions, warp_exact
from .orbit import gl_matrix

SPHERE_STACKS, SPHERE_SLICES = 8, 12
RADIUS_PER_SPACING = 0.28      # sphere radius as a fraction of the smallest drawn probe spacing
MAX_SPHERES = 4096             # beyond this many, every stride-th probe per axis
BOX_COLOUR = (0.85, 0.85, 0.9, 1.0)


@dataclass(frozen=True)
class ProbeSelection:
    """Which probes the view draws: their indices (i + nx (j + ny k), ascending), the stride per
    axis, and how many probes the grid has and how many of them lie in visible medium."""
    indices: np.ndarray
    stride: int
    visible: int
    total: int


def visible_cells(grid: tuple[int, int, int], box, volume, alpha: np.ndarray,
                  density_scale: float, planes: tuple | None = None) -> np.ndarray:
    """bool (nz, ny, nx): the probe's cell (the box of one probe spacing around it; with an
    adaptive layout's `planes`, one texel of the warped coordinate: halfway to each neighbour)
    holds a voxel whose density the transfer function's opacity makes visible (alpha > 0 at
    either table entry it interpolates between)."""
    nx, ny, nz = grid
    out = np.zeros((nz, ny, nx), bool)
    if density_scale <= 0:
        return out
    # several channels (`alpha` an app.channels.ChannelTables): visible where any shown one is
    pairs = ([(volume.channel(c), t[:, 3]) for c, (t, on) in
              enumerate(zip(alpha.tables, alpha.on)) if on] if hasattr(alpha, "tables")
             else [(volume.data, alpha)])
    voxels = None
    for data, channel_alpha in pairs:
        positive = np.asarray(channel_alpha) > 0
        n = len(positive)
        i0 = np.clip((data * np.float32(n - 1)).astype(np.int32), 0, n - 1)
        seen = positive[i0] | positive[np.minimum(i0 + 1, n - 1)]
        voxels = seen if voxels is None else voxels | seen
    if voxels is None or not voxels.any():
        return out
    he = np.asarray(volume.half_extent, np.float64)
    low, high = (-he, he) if box is None else (np.asarray(box[0], np.float64),
                                                np.asarray(box[1], np.float64))
    cells = []
    for axis, (count, dim) in enumerate(zip(grid, volume.dims)):
        centres = (np.arange(dim) + 0.5) / dim * 2 * he[axis] - he[axis]
        size = max(high[axis] - low[axis], 1e-12)
        fraction = (centres - low[axis]) / size
        if planes is not None:   # lib/probe_warp.glsl: the cell in the textures' coordinates
            inside_box = (fraction >= 0) & (fraction < 1)
            fraction = np.where(inside_box, warp_exact(planes[axis], fraction), -1.0)
        cells.append(np.floor(fraction * count).astype(np.int64))
    cx, cy, cz = cells
    inside = lambda c, n: (c >= 0) & (c < n)  # noqa: E731
    zs, ys, xs = np.nonzero(voxels[np.ix_(inside(cz, nz), inside(cy, ny), inside(cx, nx))])
    kz, ky, kx = cz[inside(cz, nz)][zs], cy[inside(cy, ny)][ys], cx[inside(cx, nx)][xs]
    out[kz, ky, kx] = True
    return out


def select_probes(grid: tuple[int, int, int], visible: np.ndarray,
                  max_spheres: int = MAX_SPHERES) -> ProbeSelection:
    """The probes to draw: the visible ones (all when none is), every stride-th per axis with the
    smallest stride that leaves at most max_spheres."""
    nx, ny, nz = grid
    total = nx * ny * nz
    shown = visible if visible.any() else np.ones_like(visible)
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    stride = 1
    while True:
        o = stride // 2
        keep = shown & (i % stride == o) & (j % stride == o) & (k % stride == o)
        if keep.sum() <= max_spheres or stride >= max(grid):
            break
        stride += 1
    return ProbeSelection(np.flatnonzero(keep.ravel()), stride, int(visible.sum()), total)


def uv_sphere(stacks: int = SPHERE_STACKS, slices: int = SPHERE_SLICES) -> tuple[np.ndarray, np.ndarray]:
    """A low-poly unit sphere: vertices (n, 3) float32 and triangle indices (m, 3) uint32."""
    theta = np.linspace(0.0, np.pi, stacks + 1)
    phi = np.linspace(0.0, 2 * np.pi, slices + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    vertices = np.stack([np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)], axis=-1)
    index = np.arange((stacks + 1) * (slices + 1)).reshape(stacks + 1, slices + 1)
    a, b = index[:-1, :-1], index[1:, :-1]
    c, d = index[1:, 1:], index[:-1, 1:]
    # Counter-clockwise seen from outside (GL's front faces; the back ones are culled).
    triangles = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3),
                                np.stack([a, d, c], -1).reshape(-1, 3)])
    return vertices.reshape(-1, 3).astype(np.float32), triangles.astype(np.uint32)


def probe_centres(grid: tuple[int, int, int], half_extent, box=None,
                  planes: tuple | None = None) -> np.ndarray:
    """World positions (count, 3) of probes in index order i + nx (j + ny k): the NumPy twin of
    probe_position in lib/probes.glsl. `box`: the probe box's (low, high) corners (ProbeGrid.box),
    default the volume box; `planes`: an adaptive layout's (ProbeGrid.planes), where the probes
    went; None: evenly spaced."""
    half = np.asarray(half_extent, np.float64)
    low, high = (-half, half) if box is None else (np.asarray(box[0]), np.asarray(box[1]))
    return low + probe_fractions(grid, planes) * (high - low)


def sphere_radius(grid: tuple[int, int, int], half_extent, planes: tuple | None = None) -> float:
    """RADIUS_PER_SPACING times the smallest probe spacing (an adaptive layout's closest planes)."""
    size = 2.0 * np.asarray(half_extent, np.float64)
    if planes is None:
        spacing = size / np.asarray(grid, np.float64)
    else:
        spacing = np.array([np.diff(p).min() * s if len(p) > 1 else s / len(p)
                            for p, s in zip(planes, size)])
    return float(RADIUS_PER_SPACING * spacing.min())


def box_edges(half_extent) -> np.ndarray:
    """The 12 edges of the volume box as 24 line end points, float32."""
    h = np.asarray(half_extent, np.float32)
    corners = [np.array(c, np.float32) * h for c in itertools.product((-1, 1), repeat=3)]
    lines = [(a, b) for a, b in itertools.combinations(corners, 2)
             if np.count_nonzero(a != b) == 1]
    return np.asarray(lines, np.float32).reshape(-1, 3)


class ProbeSpheres:
    def __init__(self, ctx: moderngl.Context, defines: dict | None = None):
        """`defines`: the probe layout's (ProbeGrid.defines()); draw() rebuilds for another."""
        self.ctx = ctx
        vertices, triangles = uv_sphere()
        self.vbo = ctx.buffer(vertices.tobytes())
        self.ibo = ctx.buffer(triangles.tobytes())
        self.centres = ctx.buffer(reserve=12 * 64, dynamic=True)  # per instance, grown as needed
        self.defines = None
        self.program = self.vao = None
        self.selection: ProbeSelection | None = None
        self._key = None
        self._build(defines or {"PROBE_SH_ORDER": 2})

    def _build(self, defines: dict) -> None:
        if defines == self.defines:
            return
        program = render_program(self.ctx, "probe_sphere_instanced.vert", "probe_sphere.frag",
                                  defines)
        if self.program is not None:
            self.vao.release()
            self.program.release()
        self.program, self.defines = program, dict(defines)
        self._make_vao()

    def _make_vao(self) -> None:
        if self.vao is not None:
            self.vao.release()
        self.vao = self.ctx.vertex_array(self.program, [(self.vbo, "3f", "sphere_point"),
                                                        (self.centres, "3f/i", "instance_centre")],
                                         index_buffer=self.ibo, index_element_size=4)

    def select(self, grid: ProbeGrid, resources: SceneResources) -> ProbeSelection:
        """The probes drawn (cached until the grid, the volume or the transfer function changes)."""
        scene = resources.scene
        key = (grid.grid, grid.box, grid.planes, resources.volume_version,
               scene.transfer_function, scene.channels, scene.density_scale > 0)
        if key != self._key:
            alpha = resources.table[:, 3] if resources.tables is None else resources.tables
            visible = visible_cells(grid.grid, grid.box, resources.volume, alpha,
                                    scene.density_scale, grid.planes)
            self.selection = select_probes(grid.grid, visible)
            centres = probe_centres(grid.grid, resources.volume.half_extent, grid.box,
                                    grid.planes)
            data = centres[self.selection.indices].astype(np.float32).tobytes()
            if len(data) > self.centres.size:
                self.centres.release()
                self.centres = self.ctx.buffer(data, dynamic=True)
                self._make_vao()
            elif data:
                self.centres.write(data)
            self._key = key
        return self.selection

    def draw(self, matrix: np.ndarray, grid: ProbeGrid, resources: SceneResources,
             exposure: float) -> None:
        """Draws the spheres into the bound framebuffer and viewport, depth-tested among
        themselves (the caller clears depth)."""
        self._build(grid.defines())
        selection = self.select(grid, resources)
        if len(selection.indices) == 0:
            return
        resources.bind()
        uniforms = resources.uniforms()
        uniforms.update(grid.uniforms(resources.scene.anisotropy, resources.scene.probes.sh_window,
                                      resources))
        he = 0.5 * np.asarray(uniforms["probe_box_size"])   # the probe box's half size
        radius = sphere_radius(grid.grid, he, grid.planes) * selection.stride
        uniforms.update({"sphere_radius": radius, "exposure": float(exposure)})
        grid.bind()
        set_uniforms(self.program, uniforms)
        self.program["view_projection"].write(gl_matrix(matrix))
        self.ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        self.ctx.front_face = "ccw"
        self.vao.render(moderngl.TRIANGLES, instances=len(selection.indices))
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)

    def release(self) -> None:
        for obj in (self.vao, self.vbo, self.ibo, self.centres, self.program):
            obj.release()


class BoxOutline:
    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.program = render_program(ctx, "lines.vert", "lines.frag")
        self.vbo = ctx.buffer(reserve=24 * 12)
        self.vao = ctx.vertex_array(self.program, [(self.vbo, "3f", "position")])

    def draw(self, matrix: np.ndarray, half_extent) -> None:
        self.vbo.write(box_edges(half_extent).tobytes())
        self.program["view_projection"].write(gl_matrix(matrix))
        self.program["line_colour"].value = BOX_COLOUR
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        self.vao.render(moderngl.LINES, vertices=24)

    def release(self) -> None:
        for obj in (self.vao, self.vbo, self.program):
            obj.release()
