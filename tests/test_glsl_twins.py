"""GLSL maths against their NumPy twins: glsl/lib/rng.glsl, camera.glsl and medium.glsl.

Tolerances
----------
* rng: bit for bit (integer maths; the float is the top 24 bits times 2^-24, exact in float32).
* camera: 2e-6 absolute on unit vectors, float32 arithmetic in GLSL against float64 in NumPy.
* medium, density from a float (R32F) volume texture: the GL spec leaves the precision of the
  linear-filter weights to the implementation; GPUs commonly quantise them to 8 bits (1/256).
  A weight error e on one axis moves the result by at most e times the spread of the 8 voxels
  involved, so we allow 3/256 * (max - min of those 8 voxels) + 2e-6 (float32 coordinates).
  Where the driver is Mesa llvmpipe (the CI context), which filters float textures with float
  weights, we also require the error to stay below 2e-6.
* medium, exact-uint8 (R8) volume: llvmpipe filters unorm8 textures in 8-bit fixed point: every
  result lies on the 1/255 grid and the three lerp stages (x, then y, then z) each round, so we allow
  another 3 * 0.5/255 on top of the weight bound (measured: at most 1.44/255 from exact trilinear,
  0.59/255 beyond the weight bound). At voxel centres the weights are 0 or 1 and the result is
  exact for both formats.
* sigma_t and albedo: at the density the GLSL code itself sampled, the transfer lookup is exact
  linear interpolation in float32 (texelFetch + mix): rtol 1e-5. Against the full NumPy twin the
  density tolerance above is carried through the table's steepest slope.
"""
import numpy as np
import pytest

from radiance_probes.twins import rng as nrng
from radiance_probes.twins.camera import camera_frame
from radiance_probes.gl.textures import TransferTable, volume_texture
from radiance_probes.twins.medium import albedo_at, box_intersect, density_at, sigma_t_at
from radiance_probes.io.scene_file import CameraSpec
from radiance_probes.scene.transfer import lookup
from radiance_probes.io.volume import Volume
from glsl_harness import run_kernel

# ---------------------------------------------------------------------------------------------
# rng

RNG_KERNEL = """
#include "lib/rng.glsl"
layout(std430, binding = 0) readonly buffer Keys { uint key[]; };
layout(std430, binding = 1) readonly buffer Samples { uint sample_index[]; };
layout(std430, binding = 2) writeonly buffer Out { uint o[]; };
uniform uint seed;
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    uint state = rng_seed(key[i], sample_index[i], seed);
    uint base = i * uint(1 + 2 * STEPS);
    o[base] = state;
    for (int k = 0; k < STEPS; ++k) o[base + 1u + uint(k)] = rng_next_uint(state);
    for (int k = 0; k < STEPS; ++k) o[base + 1u + uint(STEPS + k)] = floatBitsToUint(rng_next(state));
}
"""


def _rng_glsl(ctx, keys, samples, seed, steps):
    n = len(keys)
    out = run_kernel(ctx, RNG_KERNEL, [keys.astype(np.uint32), samples.astype(np.uint32)],
                     (n, 1 + 2 * steps), out_dtype=np.uint32, uniforms={"seed": int(seed)},
                     defines={"STEPS": steps})
    return out[:, 0], out[:, 1:1 + steps], out[:, 1 + steps:].view(np.float32)


def _rng_numpy(keys, samples, seed, steps):
    state = nrng.rng_seed(keys, samples, seed)
    seeded = state.copy()
    ints, floats = [], []
    for _ in range(steps):
        state, v = nrng.rng_next_uint(state)
        ints.append(v)
    for _ in range(steps):
        state, f = nrng.rng_next(state)
        floats.append(f)
    return seeded, np.stack(ints, 1), np.stack(floats, 1)


@pytest.mark.parametrize("seed", [0, 1, 12345, 0xFFFFFFFF])
def test_rng_bit_for_bit(ctx, seed):
    r = np.random.default_rng(seed & 0xFFFF)
    keys = np.concatenate([np.arange(512), [0xFFFFFFFF, 0x80000000, 0x7FFFFFFF],
                           r.integers(0, 2**32, 509)]).astype(np.uint32)
    samples = np.concatenate([np.zeros(256), np.arange(256), [0xFFFFFFFF, 7, 7],
                              r.integers(0, 2**32, 509)]).astype(np.uint32)
    steps = 8
    g_seed, g_int, g_float = _rng_glsl(ctx, keys, samples, seed, steps)
    n_seed, n_int, n_float = _rng_numpy(keys, samples, seed, steps)
    np.testing.assert_array_equal(g_seed, n_seed)
    np.testing.assert_array_equal(g_int, n_int)
    np.testing.assert_array_equal(g_float.view(np.uint32), n_float.view(np.uint32))
    assert g_float.dtype == np.float32 and g_float.min() >= 0.0 and g_float.max() < 1.0
    # different keys give different streams
    assert len(np.unique(g_seed)) == len(np.unique(np.stack([keys, samples], 1), axis=0))


def test_rng_reference_values():
    # Independent scalar implementation of PCG-RXS-M-XS 32, in plain Python integers.
    def pcg(v):
        s = (v * 747796405 + 2891336453) & 0xFFFFFFFF
        w = (((s >> ((s >> 28) + 4)) ^ s) * 277803737) & 0xFFFFFFFF
        return (w >> 22) ^ w

    for key, sample, seed in [(0, 0, 0), (1, 2, 3), (0xFFFFFFFF, 0xFFFFFFFF, 0xFFFFFFFF), (640, 17, 99)]:
        expected = pcg(key ^ pcg(sample ^ pcg(seed)))
        assert int(nrng.rng_seed(key, sample, seed)) == expected
        state = expected
        np_state = np.uint32(expected)
        for _ in range(5):
            state = (state * 747796405 + 2891336453) & 0xFFFFFFFF
            w = (((state >> ((state >> 28) + 4)) ^ state) * 277803737) & 0xFFFFFFFF
            value = (w >> 22) ^ w
            np_state, f = nrng.rng_next(np_state)
            assert int(np_state) == state
            assert float(f) == (value >> 8) / 2**24


def test_rng_uniformity(ctx):
    streams, steps = 2000, 50  # 1e5 draws
    keys = np.arange(streams, dtype=np.uint32)
    _, _, u = _rng_glsl(ctx, keys, np.zeros(streams, np.uint32), 42, steps)
    u = u.ravel().astype(np.float64)
    assert len(u) == 100_000
    assert abs(u.mean() - 0.5) < 0.005  # sd of the mean is 0.0009
    assert abs(u.var() - 1 / 12) < 0.002
    counts = np.bincount((u * 16).astype(int), minlength=16)
    expected = len(u) / 16
    chi2 = float(((counts - expected) ** 2 / expected).sum())
    assert chi2 < 37.7, chi2  # chi-square, 15 degrees of freedom, p = 0.001
    # consecutive draws are not correlated
    m = u.reshape(streams, steps)
    assert abs(np.corrcoef(m[:, :-1].ravel(), m[:, 1:].ravel())[0, 1]) < 0.02
    # first draws of neighbouring keys are not correlated either
    assert abs(np.corrcoef(m[:-1, 0], m[1:, 0])[0, 1]) < 0.1


# ---------------------------------------------------------------------------------------------
# camera

CAMERA_KERNEL = """
#include "lib/camera.glsl"
layout(std430, binding = 0) readonly buffer In { float px[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 d = camera_ray_direction(vec2(px[2u * i], px[2u * i + 1u]));
    o[3u * i] = d.x; o[3u * i + 1u] = d.y; o[3u * i + 2u] = d.z;
}
"""

CAMERAS = [
    CameraSpec(),
    CameraSpec(eye=(1.5, -0.7, 2.0), target=(0.1, 0.2, -0.3), up=(0.2, 1.0, 0.1), fov_y=60.0,
               width=37, height=21),
    CameraSpec(eye=(0.0, 0.0, -3.0), target=(0.0, 0.0, 0.0), up=(1.0, 0.0, 0.0), fov_y=20.0,
               width=8, height=30),
]


def _pixel_points(w, h):
    """Pixel corners and centres, in pixels, (0, 0) the top-left corner."""
    cx, cy = np.meshgrid(np.arange(w + 1, dtype=np.float64), np.arange(h + 1, dtype=np.float64))
    mx, my = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    return (np.concatenate([cx.ravel(), mx.ravel()]), np.concatenate([cy.ravel(), my.ravel()]))


@pytest.mark.parametrize("spec", CAMERAS, ids=["default", "oblique-non-square", "tall"])
def test_camera_ray_direction(ctx, spec):
    frame = camera_frame(spec)
    px, py = _pixel_points(frame.width, frame.height)
    pts = np.stack([px, py], 1).astype(np.float32)
    got = run_kernel(ctx, CAMERA_KERNEL, [pts.ravel()], (len(pts), 3), uniforms=frame.uniforms(),
                     count=len(pts))
    want = frame.ray_directions(px, py)
    np.testing.assert_allclose(got, want, atol=2e-6, rtol=0)
    np.testing.assert_allclose(np.linalg.norm(got, axis=1), 1.0, atol=1e-6)

    # Geometry, independently of the twins.
    w, h = frame.width, frame.height
    eye, target, up = (np.asarray(v, np.float64) for v in (spec.eye, spec.target, spec.up))
    fwd = (target - eye) / np.linalg.norm(target - eye)
    up_perp = up - fwd * np.dot(up, fwd)
    up_perp /= np.linalg.norm(up_perp)
    right = np.cross(fwd, up_perp)
    d = frame.ray_directions(np.array([w / 2, w / 2, w / 2, 0.0, w]),
                             np.array([h / 2, 0.0, h, h / 2, h / 2]))
    centre, top, bottom, left, rightmost = d
    np.testing.assert_allclose(centre, fwd, atol=1e-6)
    half_fov = np.radians(spec.fov_y) / 2
    assert np.degrees(np.arccos(np.clip(top @ fwd, -1, 1))) == pytest.approx(np.degrees(half_fov), abs=1e-4)
    assert np.degrees(np.arccos(np.clip(bottom @ fwd, -1, 1))) == pytest.approx(np.degrees(half_fov), abs=1e-4)
    # the horizontal field of view follows the aspect ratio
    assert np.arctan2(rightmost @ right, rightmost @ fwd) == pytest.approx(
        np.arctan(np.tan(half_fov) * w / h), abs=2e-6)
    assert left @ right < 0 < rightmost @ right
    # row 0 is at the top: a ray through the top row points more along +up than the bottom row's
    assert top @ up_perp > 0 > bottom @ up_perp
    g = got[len(px) - w * h:].reshape(h, w, 3)  # pixel centres, [row, column]
    assert np.all(g[0] @ up_perp > g[-1] @ up_perp)
    assert np.all(g[:, 0] @ right < g[:, -1] @ right)


# ---------------------------------------------------------------------------------------------
# medium

MEDIUM_KERNEL = """
#include "lib/medium.glsl"
layout(std430, binding = 0) readonly buffer In { float p[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 x = vec3(p[3u * i], p[3u * i + 1u], p[3u * i + 2u]);
    vec3 a = albedo_at(x);
    o[5u * i] = density_at(x);
    o[5u * i + 1u] = sigma_t_at(x);
    o[5u * i + 2u] = a.r; o[5u * i + 3u] = a.g; o[5u * i + 4u] = a.b;
}
"""

BOX_KERNEL = """
#include "lib/medium.glsl"
layout(std430, binding = 0) readonly buffer In { float r[]; };
layout(std430, binding = 1) writeonly buffer Out { float o[]; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    float t_near, t_far;
    bool hit = box_intersect(vec3(r[6u * i], r[6u * i + 1u], r[6u * i + 2u]),
                             vec3(r[6u * i + 3u], r[6u * i + 4u], r[6u * i + 5u]), t_near, t_far);
    o[3u * i] = t_near; o[3u * i + 1u] = t_far; o[3u * i + 2u] = hit ? 1.0 : 0.0;
}
"""

SPACING = (1.0, 2.0, 0.5)
DENSITY_SCALE = 37.0
ALBEDO = 0.8


def _float_volume(seed=1):
    data = np.random.default_rng(seed).uniform(size=(3, 4, 5)).astype(np.float32)  # [z, y, x]
    return Volume(data, SPACING, "random", (0.0, 1.0), "float32", 0.0, 1.0)


def _uint8_volume(seed=2):
    raw = np.random.default_rng(seed).integers(0, 256, size=(4, 3, 6)).astype(np.uint8)
    return Volume((raw / 255.0).astype(np.float32), (0.7, 1.0, 1.3), "random_uint8",
                  (0.0, 255.0), "uint8", 0.0, 255.0)


def _table(n=7, seed=3):
    return np.random.default_rng(seed).uniform(size=(n, 4)).astype(np.float32)


def _corner_spread(volume, points):
    """max - min of the 8 voxels trilinear filtering reads at each point (clamped to the edge)."""
    uvw = points / (2.0 * volume.half_extent.astype(np.float64)) + 0.5
    base = np.floor(uvw * np.array(volume.dims) - 0.5).astype(np.int64)
    vals = []
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                ix = np.clip(base[:, 0] + dx, 0, volume.dims[0] - 1)
                iy = np.clip(base[:, 1] + dy, 0, volume.dims[1] - 1)
                iz = np.clip(base[:, 2] + dz, 0, volume.dims[2] - 1)
                vals.append(volume.data[iz, iy, ix])
    vals = np.stack(vals)
    return vals.max(0).astype(np.float64) - vals.min(0)


def _voxel_centres(volume):
    nx, ny, nz = volume.dims
    z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    uvw = np.stack([(x + 0.5) / nx, (y + 0.5) / ny, (z + 0.5) / nz], -1).reshape(-1, 3)
    return (uvw - 0.5) * 2 * volume.half_extent.astype(np.float64)


def _run_medium(ctx, volume, table, points, albedo=ALBEDO, defines=None, texture_table=None):
    """density, sigma_t and albedo at `points`; `texture_table`: another table in the texture
    (the storage buffer keeps `table`), to see which of the two a build reads."""
    vt = volume_texture(ctx, volume)
    tt = TransferTable(ctx, table)
    other = None if texture_table is None else TransferTable(ctx, texture_table)
    try:
        vt.use(0)
        tt.use(1)
        if other is not None:
            other.texture.use(1)
        uniforms = {"volume_density": 0, "transfer_function": 1, "transfer_size": len(table),
                    "density_scale": DENSITY_SCALE, "albedo": albedo,
                    "box_half_extent": tuple(float(v) for v in volume.half_extent)}
        pts = np.ascontiguousarray(points, np.float32)
        out = run_kernel(ctx, MEDIUM_KERNEL, [pts.ravel()], (len(pts), 5), uniforms=uniforms,
                         count=len(pts), defines=defines)
    finally:
        for obj in (vt, tt, other):
            if obj is not None:
                obj.release()
    return out[:, 0], out[:, 1], out[:, 2:]


def _points(volume, n=4000, seed=4):
    he = volume.half_extent.astype(np.float64)
    r = np.random.default_rng(seed)
    inside = r.uniform(-1, 1, (n, 3)) * he
    outside = r.uniform(-1.15, 1.15, (n // 4, 3)) * he  # partly slightly outside the box
    pts = np.concatenate([inside, outside, _voxel_centres(volume)])
    return pts.astype(np.float32).astype(np.float64)  # exactly what the GPU gets


@pytest.mark.parametrize("kind", ["float", "uint8"])
def test_medium_matches_numpy(ctx, kind):
    volume = _float_volume() if kind == "float" else _uint8_volume()
    assert volume.exact_uint8 == (kind == "uint8")  # R8 texture for the uint8 volume
    table = _table()
    pts = _points(volume)
    d, sigma_t, alb = _run_medium(ctx, volume, table, pts)

    want_d = density_at(volume, pts)
    spread = _corner_spread(volume, pts)
    tol = 3 / 256 * spread + 2e-6
    if kind == "uint8":
        tol += 1.5 / 255
    err = np.abs(d - want_d)
    assert np.all(err <= tol), (err.max(), np.argmax(err - tol))
    if kind == "float" and "llvmpipe" in ctx.info["GL_RENDERER"]:
        assert err.max() < 2e-6
    # voxel centres: exact
    nc = volume.data.size
    np.testing.assert_allclose(d[-nc:], volume.data.ravel(), atol=1e-6, rtol=0)

    # sigma_t and albedo: exact transfer lookup at the density the shader sampled ...
    rows = lookup(table, d.astype(np.float64))
    np.testing.assert_allclose(sigma_t, DENSITY_SCALE * rows[:, 3], rtol=1e-5, atol=1e-5 * DENSITY_SCALE)
    np.testing.assert_allclose(alb, ALBEDO * rows[:, :3], rtol=1e-5, atol=1e-6)
    # ... and the full twins, with the density tolerance carried through the steepest table slope.
    slope = np.abs(np.diff(table.astype(np.float64), axis=0)).max(0) * (len(table) - 1)
    ws = sigma_t_at(volume, table, DENSITY_SCALE, pts)
    assert np.all(np.abs(sigma_t - ws) <= DENSITY_SCALE * (slope[3] * tol + 1e-5))
    wa = albedo_at(volume, table, ALBEDO, pts)
    assert np.all(np.abs(alb - wa) <= ALBEDO * (slope[:3] * tol[:, None] + 1e-5))


def test_constant_table_is_exact(ctx):
    # Equal table entries give exactly that entry: an albedo of 1 stays exactly 1 (a white furnace
    # over millions of bounces depends on it), and sigma_t is exactly density_scale * alpha.
    volume = _float_volume()
    table = np.tile(np.array([[1.0, 1.0, 1.0, 0.75]], np.float32), (5, 1))
    d, sigma_t, alb = _run_medium(ctx, volume, table, _points(volume, n=1000), albedo=1.0)
    assert np.all(alb == 1.0)
    assert np.all(sigma_t == np.float32(DENSITY_SCALE * 0.75))
    assert d.min() < 0.2 and d.max() > 0.8  # the densities did vary


def test_transfer_table_binding_matches_the_shader():
    """Compute passes read the transfer table from the storage buffer TransferTable.use binds."""
    import re
    from radiance_probes.gl.textures import TRANSFER_TABLE_BINDING
    from radiance_probes.paths import GLSL_DIR
    text = (GLSL_DIR / "lib" / "medium.glsl").read_text()
    bindings = re.findall(r"binding = (\d+)\) readonly buffer TransferTable", text)
    assert bindings == [str(TRANSFER_TABLE_BINDING)]


def test_transfer_buffer_only_on_a_gpu_with_its_binding():
    from types import SimpleNamespace
    from radiance_probes.gl.shaders import transfer_from_buffer

    def device(renderer, bindings):
        return SimpleNamespace(info={"GL_RENDERER": renderer,
                                     "GL_MAX_SHADER_STORAGE_BUFFER_BINDINGS": bindings})
    assert transfer_from_buffer(device("NVIDIA H100 80GB HBM3/PCIe/SSE2", 96))
    assert not transfer_from_buffer(device("NVIDIA H100 80GB HBM3/PCIe/SSE2", 8))   # GL's minimum
    assert not transfer_from_buffer(device("llvmpipe (LLVM 15.0.7, 256 bits)", 80))


@pytest.mark.parametrize("from_buffer", [0, 1])
def test_transfer_lookup_reads_the_table_it_names(ctx, from_buffer):
    """TRANSFER_FROM_BUFFER 1 reads the storage buffer, 0 the texture: with the texture holding the
    table halved, sigma_t follows the buffer's table or exactly half of it."""
    volume = _float_volume()
    table = _table()
    pts = _points(volume, n=500)
    _, want, _ = _run_medium(ctx, volume, table, pts)
    _, got, _ = _run_medium(ctx, volume, table, pts, defines={"TRANSFER_FROM_BUFFER": from_buffer},
                            texture_table=table * 0.5)
    assert want.max() > 0
    np.testing.assert_array_equal(got, want if from_buffer else want * np.float32(0.5))


def test_density_twin_follows_spec():
    """The NumPy twin itself: cell-centred, trilinear between centres, clamped beyond them."""
    volume = _float_volume()
    data = volume.data.astype(np.float64)
    he = volume.half_extent.astype(np.float64)
    nx, ny, nz = volume.dims

    def world(ix, iy, iz):  # voxel index (may be fractional) to world position
        return (np.array([(ix + 0.5) / nx, (iy + 0.5) / ny, (iz + 0.5) / nz]) - 0.5) * 2 * he

    np.testing.assert_allclose(density_at(volume, _voxel_centres(volume)), data.ravel(), atol=1e-12)
    assert density_at(volume, world(1.5, 2, 1)) == pytest.approx((data[1, 2, 1] + data[1, 2, 2]) / 2)
    assert density_at(volume, world(3, 0.25, 2)) == pytest.approx(0.75 * data[2, 0, 3] + 0.25 * data[2, 1, 3])
    assert density_at(volume, world(0, 1, 0.5)) == pytest.approx((data[0, 1, 0] + data[1, 1, 0]) / 2)
    # between the box face and the outermost centres, and beyond the box: the edge voxel
    for p in (world(-0.4, 0, 0), world(-3, 0, 0), world(nx - 1 + 0.4, ny - 1, nz - 1)):
        ix, iy, iz = np.clip(np.round((p / (2 * he) + 0.5) * [nx, ny, nz] - 0.5), 0, [nx - 1, ny - 1, nz - 1]).astype(int)
        assert density_at(volume, p) == pytest.approx(data[iz, iy, ix])
    # the corner of the box is the corner voxel
    assert density_at(volume, he) == pytest.approx(data[-1, -1, -1])
    assert density_at(volume, -he) == pytest.approx(data[0, 0, 0])


def test_box_intersect_matches_numpy(ctx):
    volume = _float_volume()
    he64 = volume.half_extent.astype(np.float64)
    r = np.random.default_rng(6)
    n = 3000
    origins = np.concatenate([r.uniform(-2, 2, (n, 3)), r.uniform(-1, 1, (n // 4, 3)) * he64])
    dirs = r.normal(size=(len(origins), 3))
    # axis-aligned and in-plane directions (zero components, including -0.0)
    dirs[: n // 3, 0] = 0.0
    dirs[n // 3: n // 2, 1:] = 0.0
    dirs[n // 2: n // 2 + 50, 2] = -0.0
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    o32 = origins.astype(np.float32)
    d32 = dirs.astype(np.float32)
    rays = np.concatenate([o32, d32], 1)
    volume_tex = volume_texture(ctx, volume)  # box_intersect needs no texture; keep the program valid
    try:
        out = run_kernel(ctx, BOX_KERNEL, [rays.ravel()], (len(rays), 3),
                         uniforms={"box_half_extent": tuple(float(v) for v in volume.half_extent)},
                         count=len(rays))
    finally:
        volume_tex.release()
    t_near, t_far, hit = out[:, 0], out[:, 1], out[:, 2] > 0.5
    wn, wf, wh = box_intersect(he64, o32.astype(np.float64), d32.astype(np.float64))
    assert 0.2 < wh.mean() < 0.9  # both hits and misses are tested
    clear = np.abs(wf - wn) > 1e-4  # away from grazing rays, where float32 may decide either way
    np.testing.assert_array_equal(hit[clear], wh[clear])
    both = hit & wh
    np.testing.assert_allclose(t_near[both], wn[both], atol=2e-6, rtol=2e-6)
    np.testing.assert_allclose(t_far[both], wf[both], atol=2e-6, rtol=2e-6)
    # origins inside the box start at 0
    inside = np.all(np.abs(o32) < he64, axis=1)
    assert inside.sum() > 100 and np.all(t_near[inside] == 0.0) and np.all(hit[inside])
    # entry points of rays from outside lie on the box surface
    outside_hits = both & ~inside & (wn > 0)
    p = o32[outside_hits] + t_near[outside_hits, None] * d32[outside_hits]
    assert np.all(np.abs(np.max(np.abs(p) / he64, axis=1) - 1.0) < 1e-5)
