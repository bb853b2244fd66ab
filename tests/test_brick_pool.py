"""The brick pool and page table (glsl/lib/brick_pool.glsl) against its NumPy twin
(app/twins/brick_pool.py), and both against the whole texture's trilinear filtering: at random
points and on the bricks' faces, edges and corners, where the seams are."""
from __future__ import annotations

import moderngl
import numpy as np
import pytest

from radiance_probes.gl.brick_pool import BrickPool
from radiance_probes.twins.brick_pool import (CONSTANT, bricked_sample, bricked_voxel,
                                              constant_bricks, pack, slot_grid)
from radiance_probes.twins.medium import trilinear
from glsl_harness import run_kernel

BRICK = 8
DIMS = (37, 29, 21)   # x, y, z: no axis a multiple of the brick


def _data(channels: int = 1, seed: int = 3) -> np.ndarray:
    """Smooth random densities with a vacuum corner and a constant slab, so that some bricks
    are constant (vacuum and another value) and others border them."""
    r = np.random.default_rng(seed)
    nx, ny, nz = DIMS
    shape = (nz, ny, nx) + ((channels,) if channels > 1 else ())
    d = r.uniform(0.0, 1.0, shape).astype(np.float32)
    d[:, :16, :24] = 0.0              # vacuum: bricks x < 3, y < 2 (those of x < 2 constant)
    d[:, 16:, :] = 0.625              # a constant slab (y >= 16): bricks y = 3 are constant
    return d


def _seam_points(n: int, seed: int = 5) -> np.ndarray:
    """Texture coordinates (n, 3): per axis a random value, or a brick boundary (b B), or half
    a voxel either side of one (where the filter's support crosses it), or a hair off one, or
    the volume's faces and a little beyond; so points on faces, edges and corners of bricks."""
    r = np.random.default_rng(seed)
    dims = np.asarray(DIMS, np.float64)
    t = r.uniform(-0.05, 1.05, (n, 3)) * dims
    for a in range(3):
        kind = r.integers(0, 6, n)
        boundary = r.integers(0, int(np.ceil(dims[a] / BRICK)) + 1, n) * BRICK
        offsets = np.choose(r.integers(0, 5, n), [0.0, 0.5, -0.5, 1e-4, -1e-4])
        t[:, a] = np.where(kind < 4, np.clip(boundary + offsets, -0.3, dims[a] + 0.3), t[:, a])
        t[:, a] = np.where(kind == 4, r.choice([0.0, dims[a], 0.5, dims[a] - 0.5], n), t[:, a])
    return (t / dims).astype(np.float32).astype(np.float64)   # what the GPU gets


def _whole(data: np.ndarray, uvw: np.ndarray) -> np.ndarray:
    coord = uvw * np.asarray(DIMS, np.float64) - 0.5
    if data.ndim == 3:
        return trilinear(data, coord)[:, None]
    return np.stack([trilinear(data[..., c], coord) for c in range(data.shape[3])], -1)


def test_constant_bricks_need_constant_neighbours():
    lo = np.zeros((3, 3, 3))
    hi = np.zeros((3, 3, 3))
    hi[0, 0, 0] = 1.0                  # one brick varies: its neighbours' aprons read it
    c = constant_bricks(lo, hi)
    assert not c[0, 0, 0] and not c[1, 1, 1] and not c[0, 1, 1]
    assert c[2, 2, 2] and c[0, 0, 2] and c[2, 0, 0]
    lo2, hi2 = lo.copy(), lo.copy()
    lo2[2, 2, 2] = hi2[2, 2, 2] = 0.5  # constant, but another value than its neighbours
    c2 = constant_bricks(lo2, hi2)
    assert not c2[2, 2, 2] and not c2[1, 1, 1] and c2[0, 0, 0]


def test_slot_grid_holds_the_slots_within_the_side():
    for n in (1, 2, 7, 8, 9, 27, 100, 1000, 4096):
        g = slot_grid(n, 64, 16384)
        assert g[0] * g[1] * g[2] >= n and max(g) * 66 <= 16384
    assert slot_grid(313 * 64, 64, 2048)[2] <= 2048 // 66
    with pytest.raises(ValueError, match="more slots than one 3D texture"):
        slot_grid(31 ** 3 + 1, 64, 2048)


@pytest.mark.parametrize("channels", [1, 3])
def test_twin_bricked_equals_whole_texture(channels):
    data = _data(channels)
    packed = pack(data, BRICK)
    counts = packed.table.shape
    constant = (packed.table & CONSTANT) != 0
    assert constant.any() and (~constant).any()   # both kinds of brick are sampled
    assert len(packed.constants) >= 2              # vacuum and the slab's value
    uvw = _seam_points(20000)
    got = bricked_sample(packed, uvw)
    want = _whole(data, uvw)
    assert np.abs(got - want).max() < 1e-5
    # every voxel through bricked_voxel (visible_region.comp's texelFetch)
    v = np.stack(np.meshgrid(*(np.arange(n) for n in DIMS), indexing="ij"), -1).reshape(-1, 3)
    vals = bricked_voxel(packed, v)
    ref = data[v[:, 2], v[:, 1], v[:, 0]].reshape(len(v), -1)
    assert np.array_equal(vals, ref.astype(np.float64))
    assert counts == (3, 4, 5)


def test_twin_constant_brick_detection_is_exact_where_it_claims():
    """A brick the page table calls constant reads its constant; the whole volume agrees there."""
    data = _data()
    packed = pack(data, BRICK)
    for z, y, x in np.argwhere((packed.table & CONSTANT) != 0):
        lo = [max(a * BRICK - 1, 0) for a in (z, y, x)]
        hi = [a * BRICK + BRICK + 1 for a in (z, y, x)]
        block = data[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
        value = packed.constants[int(packed.table[z, y, x]) & ~CONSTANT][0]
        assert np.all(block == value)


SAMPLE_KERNEL = """
#include "lib/brick_pool.glsl"
uniform sampler3D whole;
layout(std430, binding = 0) readonly buffer In { float uvw[]; };
layout(std430, binding = 1) writeonly buffer Out { vec4 o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 p = vec3(uvw[3u * i], uvw[3u * i + 1u], uvw[3u * i + 2u]);
    o[2u * i] = bricked_sample(p);
    o[2u * i + 1u] = texture(whole, p);
}
"""

VOXEL_KERNEL = """
#include "lib/brick_pool.glsl"
layout(std430, binding = 0) readonly buffer In { int v[]; };
layout(std430, binding = 1) writeonly buffer Out { vec4 o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    o[i] = bricked_voxel(ivec3(v[3u * i], v[3u * i + 1u], v[3u * i + 2u]));
}
"""


def _whole_texture(ctx, data):
    channels = 1 if data.ndim == 3 else data.shape[3]
    tex = ctx.texture3d(DIMS, channels, np.ascontiguousarray(data, np.float32).tobytes(),
                        dtype="f4")
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    tex.repeat_x = tex.repeat_y = tex.repeat_z = False
    return tex


def _corner_spread(data, uvw):
    """Largest difference between the 8 voxels the filter blends at each point (the room the
    texture unit's fixed-point weights have: llvmpipe snaps them to 1/256)."""
    coord = uvw * np.asarray(DIMS, np.float64) - 0.5
    base = np.floor(coord).astype(np.int64)
    vals = []
    for d in np.ndindex(2, 2, 2):
        i = [np.clip(base[:, a] + d[a], 0, DIMS[a] - 1) for a in range(3)]
        vals.append(data[i[2], i[1], i[0]].reshape(len(uvw), -1))
    vals = np.stack(vals)
    return vals.max(0) - vals.min(0)


@pytest.mark.parametrize("channels", [1, 4])
def test_glsl_bricked_sample_matches_twin_and_whole_texture(ctx, channels):
    data = _data(channels)
    packed = pack(data, BRICK)
    pool = BrickPool.from_packed(ctx, packed)
    whole = _whole_texture(ctx, data)
    try:
        pool.use()
        whole.use(5)
        uvw = _seam_points(6000)
        out = run_kernel(ctx, SAMPLE_KERNEL, [uvw.astype(np.float32).ravel()], (len(uvw), 2, 4),
                         uniforms={**pool.uniforms(), "whole": 5}, count=len(uvw),
                         defines={"VOLUME_BRICKED": 1})
        v = np.stack(np.meshgrid(*(np.arange(n) for n in DIMS), indexing="ij"),
                     -1).reshape(-1, 3).astype(np.int32)
        voxels = run_kernel(ctx, VOXEL_KERNEL, [v.ravel()], (len(v), 4),
                            uniforms=pool.uniforms(), count=len(v),
                            defines={"VOLUME_BRICKED": 1})
    finally:
        pool.release()
        whole.release()
    bricked, gl_whole = out[:, 0, :channels], out[:, 1, :channels]
    twin = bricked_sample(packed, uvw)
    spread = _corner_spread(data, uvw)
    tol = 3 / 256 * spread + 2e-6
    assert np.all(np.abs(bricked - twin) <= tol)
    # the seams: the bricked volume is the whole texture, but for the float rounding of the
    # coordinates (which, with fixed-point weights, may move a weight by one step)
    diff = np.abs(bricked.astype(np.float64) - gl_whole)
    assert np.all(diff <= 1.01 / 256 * spread + 2e-6)
    assert np.mean(np.all(diff <= 2e-6, axis=1)) > 0.97
    ref = data[v[:, 2], v[:, 1], v[:, 0]].reshape(len(v), -1)
    assert np.array_equal(voxels[:, :channels], ref)
    assert pool.uploads == int(np.sum((packed.table & CONSTANT) == 0))


# ---- mixed levels ----------------------------------------------------------------------------

def _pyramid(channels: int = 1):
    from radiance_probes.io.brick_sources import box_filtered
    levels = [_data(channels)]
    for _ in range(2):
        levels.append(box_filtered(levels[-1]))
    return levels


def _level_map(seed: int = 2) -> np.ndarray:
    """A level per level-0 brick: 0, 1 or 2, at random, so that every kind of neighbour meets."""
    counts = tuple(-(-n // BRICK) for n in DIMS)
    return np.random.default_rng(seed).integers(0, 3, counts[::-1])


@pytest.mark.parametrize("channels", [1, 3])
def test_twin_mixed_levels_read_each_bricks_level(channels):
    from radiance_probes.twins.brick_pool import REDIRECT, mixed_reference, pack_levels
    levels = _pyramid(channels)
    which = _level_map()
    packed = pack_levels(levels, which, BRICK)
    assert packed.levels == 3 and ((packed.table[:which.shape[0]] & REDIRECT) != 0).any()
    uvw = _seam_points(20000)
    got = bricked_sample(packed, uvw)
    want = mixed_reference(levels, which, BRICK, uvw)
    assert np.abs(got - want).max() < 1e-5
    # all level 0, or all level 1: the pool is that level's whole texture
    for lv in (0, 1):
        flat = np.full_like(which, lv)
        p = pack_levels(levels, flat, BRICK)
        coord = np.clip(uvw * np.asarray(levels[lv].shape[:3][::-1]), 0,
                        np.asarray(levels[lv].shape[:3][::-1])) - 0.5
        data = levels[lv] if channels == 1 else levels[lv][..., 0]
        assert np.abs(bricked_sample(p, uvw)[:, 0] - trilinear(data, coord)).max() < 1e-5


def test_twin_mixed_voxel_ranges_hold_the_medium_over_each_cell():
    """visible_region.comp's cells between voxel centres: the medium at points inside a cell lies
    within the union of its 8 corners' bricked_voxel_range (in a coarser level's brick, the
    range of the voxels its filter blends)."""
    from radiance_probes.twins.brick_pool import bricked_voxel_range, pack_levels
    levels = _pyramid()
    which = _level_map(5)
    packed = pack_levels(levels, which, BRICK)
    r = np.random.default_rng(7)
    dims = np.asarray(DIMS)
    cells = r.integers(0, dims - 1, (4000, 3))
    lo = np.full((len(cells), 1), np.inf)
    hi = np.full((len(cells), 1), -np.inf)
    for off in np.ndindex(2, 2, 2):
        a, b = bricked_voxel_range(packed, cells + np.asarray(off))
        lo, hi = np.minimum(lo, a), np.maximum(hi, b)
    inside = (cells[:, None, :] + 0.5 + r.uniform(0, 1, (len(cells), 16, 3))) / dims
    vals = bricked_sample(packed, inside.reshape(-1, 3)).reshape(len(cells), 16)
    assert np.all(vals >= lo - 1e-6) and np.all(vals <= hi + 1e-6)
    # level 0's voxels inside their brick are their own range; on its faces, with neighbours
    from radiance_probes.twins.brick_pool import CONSTANT as C
    z, y, x = next(b for b in np.argwhere(which == 0)
                   if not packed.table[b[0], b[1], b[2]] & C)
    inner = np.array([x, y, z]) * BRICK + 2
    a, b = bricked_voxel_range(packed, inner[None])
    assert a[0, 0] == b[0, 0] == levels[0][inner[2], inner[1], inner[0]]


RANGE_KERNEL = """
#include "lib/brick_pool.glsl"
layout(std430, binding = 0) readonly buffer In { int v[]; };
layout(std430, binding = 1) writeonly buffer Out { vec4 o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec4 lo, hi;
    bricked_voxel_range(ivec3(v[3u * i], v[3u * i + 1u], v[3u * i + 2u]), lo, hi);
    o[2u * i] = lo;
    o[2u * i + 1u] = hi;
}
"""


@pytest.mark.parametrize("channels", [1, 3])
def test_glsl_mixed_levels_match_the_twin(ctx, channels):
    from radiance_probes.twins.brick_pool import bricked_voxel_range, mixed_reference, pack_levels
    levels = _pyramid(channels)
    which = _level_map(11)
    packed = pack_levels(levels, which, BRICK)
    pool = BrickPool.from_packed(ctx, packed)
    try:
        pool.use()
        assert pool.defines() == {"VOLUME_BRICKED": 1, "BRICK_LEVELS": 3}
        uvw = _seam_points(6000)
        out = run_kernel(ctx, SAMPLE_KERNEL.replace("uniform sampler3D whole;", "")
                         .replace("texture(whole, p)", "vec4(0.0)"),
                         [uvw.astype(np.float32).ravel()], (len(uvw), 2, 4),
                         uniforms=pool.uniforms(), count=len(uvw), defines=pool.defines())
        v = np.stack(np.meshgrid(*(np.arange(n) for n in DIMS), indexing="ij"),
                     -1).reshape(-1, 3).astype(np.int32)
        ranges = run_kernel(ctx, RANGE_KERNEL, [v.ravel()], (len(v), 2, 4),
                            uniforms=pool.uniforms(), count=len(v), defines=pool.defines())
    finally:
        pool.release()
    # a point on a face between bricks of two levels is in either, by the float rounding of its
    # coordinate (the medium steps there): compared off the faces (1e-4 voxels off stays in)
    t = uvw * np.asarray(DIMS, np.float64)
    off_face = np.all(np.abs(t - np.round(t / BRICK) * BRICK) > 2e-5, axis=1)
    assert off_face.mean() > 0.5
    got = out[off_face, 0, :channels]
    twin = bricked_sample(packed, uvw[off_face])
    want = mixed_reference(levels, which, BRICK, uvw[off_face])
    # fixed-point filter weights: up to 3/256 of the densities' spread (1 at most)
    assert np.all(np.abs(got - twin) <= 3 / 256 + 2e-6)
    assert np.abs(twin - want).max() < 1e-5
    lo, hi = bricked_voxel_range(packed, v.astype(np.int64))
    np.testing.assert_array_equal(ranges[:, 0, :channels], lo.astype(np.float32))
    np.testing.assert_array_equal(ranges[:, 1, :channels], hi.astype(np.float32))
