"""The probe-grid view: probes as small spheres at their centres, shaded by the probe's SH
radiance at the sphere's normal under the current exposure (glsl/probe_sphere_instanced.vert and
probe_sphere.frag), instanced; and the volume box's outline.

Readable at any grid: only probes whose cell holds visible medium are drawn (what the transfer
function makes visible; all of them when nothing is), and on grids with more of those than
MAX_SPHERES every stride-th probe along each axis, the spheres growing with the stride, so a
32^3 grid over an unseen volume is a lattice through the visible part, not a wall.

A slab (the viewer's Probe slab: an axis and a plane the user moves) draws one plane of probes,
the visible ones, each sphere sized by the probe spacing (RADIUS_PER_SPACING of it): a 64^3 or
128^3 grid reads as a sheet of probes through the volume, one plane at a time. The probe under
the mouse (probe_under) is named with what it holds (describe_probe)."""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import moderngl
import numpy as np

from radiance_probes.gl.shaders import render_program, set_uniforms
from radiance_probes.rendering.probes.bake import ProbeGrid
from radiance_probes.rendering.resources import SceneResources
from radiance_probes.twins.probe_warp import probe_fractions, warp_exact
from radiance_probes.viewer.orbit import gl_matrix

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


# The probe view's slab: "all" draws the whole grid (as a lattice), "x", "y" or "z" one plane of
# probes across that axis.
PROBE_SLAB_AXES = ("all", "x", "y", "z")


def slab_plane(grid: tuple[int, int, int], axis: str, fraction: float) -> int:
    """The plane of probes across `axis` at `fraction` (0 to 1) of the probe box: its index."""
    n = grid["xyz".index(axis)]
    return int(min(max(int(float(fraction) * n), 0), n - 1))


def select_probes(grid: tuple[int, int, int], visible: np.ndarray,
                  max_spheres: int = MAX_SPHERES,
                  slab: tuple[str, int] | None = None) -> ProbeSelection:
    """The probes to draw: the visible ones (all when none is), every stride-th per axis with the
    smallest stride that leaves at most max_spheres. `slab` (axis, plane index): only the probes of
    that plane (its visible ones; none where the plane holds no visible medium)."""
    nx, ny, nz = grid
    total = nx * ny * nz
    shown = visible if visible.any() else np.ones_like(visible)
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    if slab is not None:
        axis, plane = slab
        shown = shown & ({"x": i, "y": j, "z": k}[axis] == int(plane))
    stride = 1
    while True:
        o = stride // 2
        along = [(i, 0), (j, 1), (k, 2)]
        keep = shown.copy()
        for index, a in along:
            if slab is None or "xyz"[a] != slab[0]:   # a slab's own axis is not thinned
                keep &= index % stride == o
        if keep.sum() <= max_spheres or stride >= max(grid):
            break
        stride += 1
    return ProbeSelection(np.flatnonzero(keep.ravel()), stride, int(visible.sum()), total)


def probe_under(pixel, centres: np.ndarray, matrix: np.ndarray, width: int, height: int,
                radius: float, eye) -> int | None:
    """Of the probes at world `centres` (n, 3) drawn as spheres of world `radius`, the one under
    image point `pixel` (x, y in the render's pixels, top-left origin): the nearest to the eye of
    those whose sphere's image disk holds the point; None where none does."""
    from radiance_probes.viewer.orbit import project
    if len(centres) == 0:
        return None
    centres = np.asarray(centres, np.float64)
    at = project(matrix, centres, width, height)
    distance = np.linalg.norm(centres - np.asarray(eye, np.float64), axis=1)
    # each sphere's image disk: its centre moved by the radius along the view's up axis (row 1
    # of the view-projection matrix is the projection's scale times the camera's up)
    up = np.asarray(matrix, np.float64)[1, :3]
    up = up / max(np.linalg.norm(up), 1e-30)
    edge = project(matrix, centres + radius * up, width, height)
    with np.errstate(invalid="ignore"):
        disk = np.hypot(*(edge - at).T)
        off = np.hypot(at[:, 0] - pixel[0], at[:, 1] - pixel[1])
        hits = np.flatnonzero(np.isfinite(off) & (off <= np.maximum(disk, 2.0)))
    if len(hits) == 0:
        return None
    return int(hits[np.argmin(distance[hits])])


def describe_probe(index: int, grid: tuple[int, int, int], centre, channels: np.ndarray,
                   sh_order: int) -> list[str]:
    """What a probe holds, in words: its place, the mean radiance arriving (L00 / sqrt(4 pi)), the
    direction most light arrives from (band 1, where the order keeps it) and the sun's
    transmittance to it. `channels`: its row of ProbeGrid.coefficients() (colour packing)."""
    from radiance_probes.rendering.probes.layout import unpack_coefficients
    nx, ny, nz = grid
    i, j, k = index % nx, (index // nx) % ny, index // (nx * ny)
    coeffs, sun = unpack_coefficients(np.asarray(channels, np.float64), sh_order)
    mean = coeffs[0] / np.sqrt(4.0 * np.pi)
    lines = [f"probe ({i}, {j}, {k}) of {nx} x {ny} x {nz} at "
             f"({', '.join(f'{c:.3f}' for c in np.asarray(centre, np.float64))})",
             "mean radiance arriving: " + " ".join(f"{c:.4g}" for c in mean)]
    if sh_order >= 1 and len(coeffs) >= 4:
        lum = coeffs[:4] @ np.array([0.2126, 0.7152, 0.0722])
        d = np.array([lum[3], lum[1], lum[2]])   # Y11 ~ x, Y1-1 ~ y, Y10 ~ z
        n = np.linalg.norm(d)
        if n > 0:
            d = d / n
            lines.append(f"most light from ({d[0]:.2f}, {d[1]:.2f}, {d[2]:.2f}), "
                         f"{n / max(abs(lum[0]), 1e-30) * np.sqrt(3.0):.0%} of the mean")
    lines.append(f"sun transmittance: {float(sun):.4g}")
    return lines


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
        self.centres_drawn = np.zeros((0, 3))   # world centres of the probes drawn
        self.radius = 0.0                       # the spheres' world radius as last drawn
        self._key = None
        self._visible_key, self._visible = None, None
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

    def select(self, grid: ProbeGrid, resources: SceneResources,
               slab: tuple[str, int] | None = None) -> ProbeSelection:
        """The probes drawn (cached until the grid, the volume, the transfer function or the
        slab changes); `slab` (axis, plane index): one plane of them."""
        scene = resources.scene
        key = (grid.grid, grid.box, grid.planes, resources.volume_version,
               scene.transfer_function, scene.channels, scene.density_scale > 0, slab)
        if key != self._key:
            if self._visible_key != key[:-1]:
                alpha = resources.table[:, 3] if resources.tables is None else resources.tables
                self._visible = visible_cells(grid.grid, grid.box, resources.volume, alpha,
                                              scene.density_scale, grid.planes)
                self._visible_key = key[:-1]
            self.selection = select_probes(grid.grid, self._visible, slab=slab)
            centres = probe_centres(grid.grid, resources.volume.half_extent, grid.box,
                                    grid.planes)
            self.centres_drawn = centres[self.selection.indices]
            data = self.centres_drawn.astype(np.float32).tobytes()
            if len(data) > self.centres.size:
                self.centres.release()
                self.centres = self.ctx.buffer(data, dynamic=True)
                self._make_vao()
            elif data:
                self.centres.write(data)
            self._key = key
        return self.selection

    def draw(self, matrix: np.ndarray, grid: ProbeGrid, resources: SceneResources,
             exposure: float, slab: tuple[str, int] | None = None) -> None:
        """Draws the spheres into the bound framebuffer and viewport, depth-tested among
        themselves (the caller clears depth)."""
        self._build(grid.defines())
        selection = self.select(grid, resources, slab)
        if len(selection.indices) == 0:
            return
        resources.bind()
        uniforms = resources.uniforms()
        uniforms.update(grid.uniforms(resources.scene.anisotropy, resources.scene.probes.sh_window,
                                      resources))
        he = 0.5 * np.asarray(uniforms["probe_box_size"])   # the probe box's half size
        radius = sphere_radius(grid.grid, he, grid.planes) * selection.stride
        self.radius = radius
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
