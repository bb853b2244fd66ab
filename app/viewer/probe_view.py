"""The probe-grid view: every probe a small sphere at its centre, shaded by the probe's SH
radiance at the sphere's normal (glsl/probe_sphere.*), instanced; and the volume box's outline."""
from __future__ import annotations

import itertools

import moderngl
import numpy as np

from ..gl.shaders import render_program, set_uniforms
from ..render.probes import ProbeGrid
from ..render.resources import SceneResources
from .orbit import gl_matrix

SPHERE_STACKS, SPHERE_SLICES = 8, 12
RADIUS_PER_SPACING = 0.28      # sphere radius as a fraction of the smallest probe spacing
BOX_COLOUR = (0.85, 0.85, 0.9, 1.0)


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


def probe_centres(grid: tuple[int, int, int], half_extent, box=None) -> np.ndarray:
    """World positions (count, 3) of probes in index order i + nx (j + ny k): the NumPy twin of
    probe_position in lib/probes.glsl. `box`: the probe box's (low, high) corners (ProbeGrid.box),
    default the volume box."""
    nx, ny, nz = grid
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    ijk = np.stack([i, j, k], axis=-1).reshape(-1, 3).astype(np.float64)
    half = np.asarray(half_extent, np.float64)
    low, high = (-half, half) if box is None else (np.asarray(box[0]), np.asarray(box[1]))
    return low + (ijk + 0.5) / np.asarray(grid, np.float64) * (high - low)


def sphere_radius(grid: tuple[int, int, int], half_extent) -> float:
    spacing = 2.0 * np.asarray(half_extent, np.float64) / np.asarray(grid, np.float64)
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
        self.defines = None
        self.program = self.vao = None
        self._build(defines or {"PROBE_SH_ORDER": 2})

    def _build(self, defines: dict) -> None:
        if defines == self.defines:
            return
        program = render_program(self.ctx, "probe_sphere.vert", "probe_sphere.frag", defines)
        if self.program is not None:
            self.vao.release()
            self.program.release()
        self.program, self.defines = program, dict(defines)
        self.vao = self.ctx.vertex_array(self.program, [(self.vbo, "3f", "sphere_point")],
                                         index_buffer=self.ibo, index_element_size=4)

    def draw(self, matrix: np.ndarray, grid: ProbeGrid, resources: SceneResources,
             exposure: float) -> None:
        """Draws the spheres into the bound framebuffer and viewport, depth-tested among
        themselves (the caller clears depth)."""
        self._build(grid.defines())
        resources.bind()
        uniforms = resources.uniforms()
        uniforms.update(grid.uniforms(resources.scene.anisotropy, resources.scene.probes.sh_window,
                                      resources))
        he = 0.5 * np.asarray(uniforms["probe_box_size"])   # the probe box's half size
        uniforms.update({"sphere_radius": sphere_radius(grid.grid, he), "exposure": float(exposure)})
        grid.bind()
        set_uniforms(self.program, uniforms)
        self.program["view_projection"].write(gl_matrix(matrix))
        self.ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        self.ctx.front_face = "ccw"
        self.vao.render(moderngl.TRIANGLES, instances=grid.count)
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)

    def release(self) -> None:
        for obj in (self.vao, self.vbo, self.ibo, self.program):
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
