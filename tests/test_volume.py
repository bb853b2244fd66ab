"""Volume loaders, normalisation and the world box (SPEC.md "World and volume")."""
import re

import nrrd
import numpy as np
import pytest

from radiance_probes.gl.textures import volume_texture
from radiance_probes.io.scene_file import VolumeSpec, parse_scene
from radiance_probes.io.builtin_volumes import BUILTIN_VOLUMES
from radiance_probes.io.volume import Volume, VolumeError, normalise
from radiance_probes.io.load import load_scene_volume, load_volume
from conftest import dataset


def file_spec(path, **kw) -> VolumeSpec:
    return VolumeSpec(path=str(path), builtin=None, **kw)


def make_volume(data: np.ndarray, spacing=(1.0, 1.0, 1.0), raw_dtype="float32",
                value_range=(0.0, 1.0), name="test") -> Volume:
    return Volume(data, spacing, name, value_range, raw_dtype, 0.0, 1.0)


# ---------------------------------------------------------------------------------------------
# Loaders

def test_raw_uint8_open_scivis_naming_and_axis_order(tmp_path):
    f = tmp_path / "name_4x3x2_uint8.raw"
    f.write_bytes(bytes(range(24)))  # x fastest, then y, then z
    v = load_volume(file_spec(f))
    assert v.dims == (4, 3, 2)
    assert v.data.shape == (2, 3, 4) and v.data.dtype == np.float32
    z, y, x = np.meshgrid(np.arange(2), np.arange(3), np.arange(4), indexing="ij")
    np.testing.assert_array_equal(v.data, ((z * 12 + y * 4 + x) / 255.0).astype(np.float32))
    assert v.data[1, 2, 3] == np.float32(23 / 255) and v.data[0, 0, 1] == np.float32(1 / 255)
    assert v.value_range == (0.0, 255.0) and v.raw_dtype == "uint8" and v.exact_uint8
    assert (v.raw_min, v.raw_max) == (0.0, 23.0)
    assert v.spacing == (1.0, 1.0, 1.0) and v.name == f.name


def test_raw_uint16_little_endian_min_max(tmp_path):
    raw = np.arange(100, 100 + 5 * 2 * 3, dtype="<u2").reshape(3, 2, 5) * 7
    f = tmp_path / "vol_5x2x3_uint16.raw"
    raw.tofile(f)
    v = load_volume(file_spec(f))
    assert v.dims == (5, 2, 3) and v.raw_dtype == "uint16" and not v.exact_uint8
    lo, hi = raw.min(), raw.max()
    assert v.value_range == (float(lo), float(hi))
    np.testing.assert_allclose(v.data, (raw - lo) / (hi - lo), rtol=0, atol=1e-7)
    assert v.data.min() == 0.0 and v.data.max() == 1.0


def test_raw_float32(tmp_path):
    rng = np.random.default_rng(3)
    raw = rng.normal(size=(2, 3, 4)).astype(np.float32)
    f = tmp_path / "noise_4x3x2_float32.raw"
    raw.tofile(f)
    v = load_volume(file_spec(f))
    lo, hi = float(raw.min()), float(raw.max())
    np.testing.assert_allclose(v.data, (raw.astype(np.float64) - lo) / (hi - lo), atol=1e-7)


def test_raw_with_dims_and_dtype_given(tmp_path):
    raw = np.arange(24, dtype=np.uint8).reshape(2, 3, 4)
    f = tmp_path / "plain.raw"
    raw.tofile(f)
    v = load_volume(file_spec(f, dims=(4, 3, 2), dtype="uint8"))
    np.testing.assert_array_equal(v.data * 255, raw.astype(np.float32))


def test_npy(tmp_path):
    raw = np.linspace(-2, 3, 60).reshape(3, 4, 5).astype(np.float64)
    f = tmp_path / "vol.npy"
    np.save(f, raw)
    v = load_volume(file_spec(f))
    assert v.dims == (5, 4, 3)
    np.testing.assert_allclose(v.data, (raw + 2) / 5, atol=1e-7)


@pytest.mark.parametrize("layout", ["fortran", "big-endian"])
def test_npy_layouts(tmp_path, ctx, layout):
    raw = np.arange(60, dtype=np.float32).reshape(3, 4, 5)
    arr = np.asfortranarray(raw) if layout == "fortran" else raw.astype(">f4")
    f = tmp_path / "vol.npy"
    np.save(f, arr)
    v = load_volume(file_spec(f))
    assert v.dims == (5, 4, 3)
    np.testing.assert_allclose(v.data, raw / 59, atol=1e-7)
    t = volume_texture(ctx, v)  # texel order x fastest whatever the array's memory layout
    np.testing.assert_allclose(np.frombuffer(t.read(), np.float32), (raw / 59).ravel(), atol=1e-7)
    t.release()


def _write_nrrd(path, data, header):
    nrrd.write(str(path), data, header, index_order="C")


def test_nrrd_spacing_from_header(tmp_path):
    raw = np.arange(4 * 3 * 2, dtype=np.int16).reshape(2, 3, 4) - 5  # [z, y, x]
    f = tmp_path / "vol.nrrd"
    _write_nrrd(f, raw, {"spacings": [0.5, 2.0, 3.0]})
    v = load_volume(file_spec(f))
    assert v.dims == (4, 3, 2)
    assert v.spacing == (0.5, 2.0, 3.0)
    np.testing.assert_allclose(v.data, (raw + 5) / 23.0, atol=1e-7)
    # box extents: 2, 6, 6 -> longest 6 is 1
    np.testing.assert_allclose(v.half_extent, [1 / 6, 0.5, 0.5], rtol=1e-6)


def test_nrrd_space_directions(tmp_path):
    raw = np.zeros((2, 3, 4), np.uint8)
    raw[0, 0, 0] = 255
    f = tmp_path / "dirs.nrrd"
    _write_nrrd(f, raw, {"space": "left-posterior-superior",
                         "space directions": np.diag([1.25, 1.5, 4.0])})
    assert load_volume(file_spec(f)).spacing == (1.25, 1.5, 4.0)


@pytest.mark.parametrize("spacing", [(1.0, 1.0, 1.0), (2.0, 1.0, 0.25)])
def test_explicit_spacing_overrides_nrrd_header(tmp_path, spacing):
    f = tmp_path / "vol.nrrd"
    _write_nrrd(f, np.arange(24, dtype=np.uint8).reshape(2, 3, 4), {"spacings": [0.5, 2.0, 3.0]})
    # Through a scene too: an explicit [1, 1, 1] is an override, not "the default".
    scene = parse_scene({"volume": {"path": str(f), "spacing": list(spacing)}})
    assert load_scene_volume(scene).spacing == spacing
    assert load_volume(file_spec(f, spacing=spacing)).spacing == spacing


def test_relative_path_from_scene_folder(tmp_path):
    (tmp_path / "v_2x2x2_uint8.raw").write_bytes(bytes(8))
    scene = parse_scene({"volume": {"path": "v_2x2x2_uint8.raw"}}, base_dir=tmp_path)
    assert load_scene_volume(scene).dims == (2, 2, 2)


# ---------------------------------------------------------------------------------------------
# Errors name the file and the problem

def test_missing_file(tmp_path):
    f = tmp_path / "gone_4x4x4_uint8.raw"
    with pytest.raises(VolumeError, match=r"gone_4x4x4_uint8\.raw.*not found"):
        load_volume(file_spec(f))


def test_size_mismatch_states_both_byte_counts(tmp_path):
    f = tmp_path / "short_4x3x2_uint16.raw"
    f.write_bytes(bytes(40))
    with pytest.raises(VolumeError) as e:
        load_volume(file_spec(f))
    msg = str(e.value)
    assert "short_4x3x2_uint16.raw" in msg
    assert re.search(r"\b40 bytes\b", msg) and re.search(r"\b48\b", msg)


@pytest.mark.parametrize("name, kw", [("odd_2x2x2_uint7.raw", {}),
                                      ("plain.raw", {"dims": (2, 2, 2), "dtype": "float16"})])
def test_unknown_dtype(tmp_path, name, kw):
    f = tmp_path / name
    f.write_bytes(bytes(8))
    with pytest.raises(VolumeError, match=re.escape(name) + r".*unknown data type"):
        load_volume(file_spec(f, **kw))


def test_unknown_format(tmp_path):
    f = tmp_path / "vol.vtk"   # (.tiff was the example until TIFF stacks became a format)
    f.write_bytes(bytes(8))
    with pytest.raises(VolumeError, match=r"vol\.vtk.*format"):
        load_volume(file_spec(f))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_float_data(tmp_path, bad):
    raw = np.linspace(0, 1, 24, dtype=np.float32).reshape(2, 3, 4)
    raw[1, 2, 0] = bad
    raw[0, 1, 3] = bad
    f = tmp_path / "bad_4x3x2_float32.raw"
    raw.tofile(f)
    with pytest.raises(VolumeError, match=r"bad_4x3x2_float32\.raw.*2 voxels.*NaN or Inf"):
        load_volume(file_spec(f))
    v = load_volume(file_spec(f, replace_nonfinite=0.5))
    assert np.isfinite(v.data).all()
    # min 0 and max 1 stay the range; the replaced voxels become 0.5
    assert v.data[1, 2, 0] == 0.5 and v.data[0, 1, 3] == 0.5
    assert v.data[0, 0, 0] == 0.0 and v.data[1, 2, 3] == 1.0


def test_zero_size_npy(tmp_path):
    f = tmp_path / "empty.npy"
    np.save(f, np.zeros((3, 0, 2), np.float32))
    with pytest.raises(VolumeError, match=r"empty\.npy.*zero size"):
        load_volume(file_spec(f))


def test_npy_not_3d(tmp_path):
    f = tmp_path / "flat.npy"
    np.save(f, np.zeros((3, 2), np.float32))
    with pytest.raises(VolumeError, match=r"flat\.npy.*3D"):
        load_volume(file_spec(f))


@pytest.mark.parametrize("dims", [(0, 3, 2), (4, 3, 0)])
def test_zero_raw_dims(tmp_path, dims):
    f = tmp_path / "plain.raw"
    f.write_bytes(b"")
    with pytest.raises(VolumeError, match=r"plain\.raw.*at least 1"):
        load_volume(file_spec(f, dims=dims, dtype="uint8"))


def test_zero_dims_in_name(tmp_path):
    f = tmp_path / "flat_4x0x2_uint8.raw"
    f.write_bytes(b"")
    with pytest.raises(VolumeError, match=r"flat_4x0x2_uint8\.raw.*at least 1"):
        load_volume(file_spec(f))


def test_raw_name_without_dims(tmp_path):
    f = tmp_path / "nodims.raw"
    f.write_bytes(bytes(8))
    with pytest.raises(VolumeError, match=r"nodims\.raw.*dimensions"):
        load_volume(file_spec(f))
    with pytest.raises(VolumeError, match=r"nodims\.raw.*data type"):
        load_volume(file_spec(f, dims=(2, 2, 2)))


@pytest.mark.parametrize("dtype", [np.uint16, np.int16, np.float32])
def test_constant_non_8bit_needs_value_range(tmp_path, dtype):
    f = tmp_path / "flat.npy"
    np.save(f, np.full((2, 3, 4), 7, dtype))
    with pytest.raises(VolumeError, match=r"flat\.npy.*value_range"):
        load_volume(file_spec(f))
    v = load_volume(file_spec(f, value_range=(0.0, 14.0)))
    assert np.all(v.data == 0.5)


def test_constant_uint8_is_fine(tmp_path):
    f = tmp_path / "c_2x2x2_uint8.raw"
    f.write_bytes(bytes([51] * 8))
    assert np.all(load_volume(file_spec(f)).data == np.float32(0.2))


def test_bad_value_range_given_directly():
    with pytest.raises(VolumeError, match="where.*value range"):
        normalise(np.arange(8, dtype=np.uint16).reshape(2, 2, 2), (3.0, 3.0), "where")


def test_dims_beyond_gl_max_3d_texture_size(ctx, monkeypatch):
    limit = ctx.info["GL_MAX_3D_TEXTURE_SIZE"]
    ok = make_volume(np.broadcast_to(np.float32(0.25), (1, 1, limit)), name="at-limit")
    tex = volume_texture(ctx, ok)
    assert tex.size == (limit, 1, 1)
    tex.release()

    def no_alloc(*a, **k):
        raise AssertionError("volume_texture allocated a texture before checking the dims")
    monkeypatch.setattr(ctx, "texture3d", no_alloc)
    for shape in [(1, 1, limit + 1), (limit + 1, 1, 1), (1, limit + 1, 1)]:
        for raw_dtype, vr in [("float32", (0.0, 1.0)), ("uint8", (0.0, 255.0))]:
            big = make_volume(np.broadcast_to(np.float32(0), shape), raw_dtype=raw_dtype,
                              value_range=vr, name="huge.raw")
            with pytest.raises(VolumeError, match=rf"huge\.raw.*{limit}"):
                volume_texture(ctx, big)


def test_volume_texture_formats(ctx):
    data = (np.arange(24, dtype=np.float32).reshape(2, 3, 4) / 255.0).astype(np.float32)
    exact = make_volume(data, raw_dtype="uint8", value_range=(0.0, 255.0))
    t = volume_texture(ctx, exact)
    assert t.dtype == "nu2" and t.size == (4, 3, 2)
    np.testing.assert_array_equal(np.frombuffer(t.read(), np.uint16), np.arange(24) * 257)
    t.release()
    t = volume_texture(ctx, make_volume(data))
    assert t.dtype == "f4"
    np.testing.assert_array_equal(np.frombuffer(t.read(), np.float32), data.ravel())
    t.release()


# ---------------------------------------------------------------------------------------------
# Normalisation

def test_uint8_default_range_is_full_type_range(tmp_path):
    f = tmp_path / "v_2x2x2_uint8.raw"
    f.write_bytes(bytes([10, 11, 12, 13, 14, 15, 16, 20]))
    v = load_volume(file_spec(f))
    assert v.value_range == (0.0, 255.0)
    assert v.data.max() == np.float32(20 / 255) and v.data.min() == np.float32(10 / 255)


def test_explicit_value_range_clamps(tmp_path):
    f = tmp_path / "v_2x2x2_uint8.raw"
    f.write_bytes(bytes([0, 50, 100, 150, 200, 250, 255, 125]))
    v = load_volume(file_spec(f, value_range=(50.0, 150.0)))
    np.testing.assert_allclose(v.data.ravel(), [0, 0, 0.5, 1, 1, 1, 1, 0.75], atol=1e-7)
    assert v.value_range == (50.0, 150.0) and not v.exact_uint8
    v = load_volume(file_spec(f, value_range=(0.0, 255.0)))
    assert v.exact_uint8


def test_uint16_value_range(tmp_path):
    raw = np.array([0, 1000, 2000, 65535, 4000, 3000, 500, 100], "<u2").reshape(2, 2, 2)
    f = tmp_path / "v_2x2x2_uint16.raw"
    raw.tofile(f)
    v = load_volume(file_spec(f, value_range=(1000.0, 3000.0)))
    np.testing.assert_allclose(v.data.ravel(), [0, 0, 0.5, 1, 1, 1, 0, 0], atol=1e-7)


# ---------------------------------------------------------------------------------------------
# The world box

@pytest.mark.parametrize("dims, spacing, expected", [
    ((8, 8, 8), (1, 1, 1), (0.5, 0.5, 0.5)),
    ((10, 5, 2), (1, 1, 1), (0.5, 0.25, 0.1)),
    ((10, 10, 10), (1, 2, 4), (0.125, 0.25, 0.5)),
    ((256, 256, 133), (1.40625, 1.40625, 2.5), (0.5, 0.5, 0.5 * 133 * 2.5 / 360)),
    ((3, 7, 5), (3, 1, 2), (0.45, 0.35, 0.5)),
])
def test_half_extent(dims, spacing, expected):
    v = make_volume(np.zeros(dims[::-1], np.float32), spacing=spacing)
    he = v.half_extent
    np.testing.assert_allclose(he, expected, rtol=1e-6)
    assert he.max() == 0.5  # the longest side is exactly 1


# ---------------------------------------------------------------------------------------------
# Built-in volumes

@pytest.mark.parametrize("name", sorted(BUILTIN_VOLUMES))
def test_builtin_volumes(name):
    v = load_volume(VolumeSpec(builtin=name, size=(9, 7, 5)))
    assert v.data.shape == (5, 7, 9) and v.dims == (9, 7, 5)
    assert v.data.dtype == np.float32
    assert np.isfinite(v.data).all()
    assert v.data.min() >= 0.0 and v.data.max() <= 1.0
    if name == "empty":
        assert v.data.max() == 0.0
    else:
        assert v.data.max() > 0.5  # something is there
    np.testing.assert_allclose(v.half_extent, [0.5, 7 / 18, 5 / 18], rtol=1e-6)


def test_builtin_sheet_is_normal_to_y():
    d = load_volume(VolumeSpec(builtin="sheet", size=(9, 7, 5))).data
    assert np.all(d[:, 3, :] == 1.0) and d.sum() == 9 * 5


def test_builtin_deterministic():
    a = load_volume(VolumeSpec(builtin="cloud", size=(9, 7, 5))).data
    b = load_volume(VolumeSpec(builtin="cloud", size=(9, 7, 5))).data
    np.testing.assert_array_equal(a, b)


def test_default_scene_volume():
    v = load_scene_volume(parse_scene({"volume": {"size": [12, 10, 8]}}))
    assert v.name == "builtin:cloud" and v.dims == (12, 10, 8) and v.spacing == (1.0, 1.0, 1.0)


# ---------------------------------------------------------------------------------------------
# Real datasets (skipped when ../shared/datasets is absent)

def test_dataset_fuel():
    v = load_volume(file_spec(dataset("fuel_64x64x64_uint8.raw")))
    assert v.dims == (64, 64, 64) and v.exact_uint8
    assert 0.0 <= v.data.min() and v.data.max() <= 1.0 and v.data.max() > 0


def test_dataset_chest_ct_nrrd():
    v = load_volume(file_spec(dataset("lidc2_chest_ct_256x256x133.nrrd")))
    assert v.dims == (256, 256, 133) and v.data.shape == (133, 256, 256)
    assert v.spacing == (1.40625, 1.40625, 2.5)
    assert v.raw_dtype == "uint8"
    np.testing.assert_allclose(v.half_extent, [0.5, 0.5, 0.5 * 133 * 2.5 / 360], rtol=1e-6)


def test_volume_beyond_the_memory_left_is_refused_with_why():
    from radiance_probes.gl.textures import check_volume_fits
    check_volume_fits("ct", (512, 512, 400), 4, 2048, 512 * 512 * 400 * 4, "GPU memory")  # fits
    with pytest.raises(VolumeError, match=r"ct: the 512 x 512 x 401 volume needs 0\.39 GiB .*"
                                          r"more than the 0\.39 GiB of GPU memory.*bricking"):
        check_volume_fits("ct", (512, 512, 401), 4, 2048, 512 * 512 * 400 * 4, "GPU memory")
    with pytest.raises(VolumeError, match="GL_MAX_3D_TEXTURE_SIZE of 2048.*bricking"):
        check_volume_fits("ct", (4096, 8, 8), 2, 2048, None, "GPU memory")
    check_volume_fits("ct", (2048, 8, 8), 2, 2048, None, "GPU memory")   # None: cannot tell


@pytest.mark.parametrize("dtype, ranges", [
    ("uint16", [(0, 65535), (0, 4095), (100, 1000), (-5, 70000), (12345, 12346),
                (-2 ** 23, 2 ** 23), (65534, 65535)]),
    ("int16", [(-32768, 32767), (-1000, 3000), (0, 1), (-2 ** 23, 2 ** 23 - 7)]),
    ("uint8", [(0, 255), (3, 200)]),
    ("int8", [(-128, 127), (-1, 1)])])
def test_normalise_in_float32_equals_float64_for_every_small_integer(dtype, ranges):
    """normalise maps 8- and 16-bit integers with a whole-number range in float32 arithmetic
    (app/io/volume.py float32_exact; the bricked upload maps this way in its reading processes):
    bit for bit the float64 mapping rounded to float32, for every value of the type."""
    from radiance_probes.io.volume import float32_exact
    info = np.iinfo(dtype)
    raw = np.arange(info.min, info.max + 1).astype(dtype).reshape(-1, 1, 1)
    for lo, hi in ranges:
        assert float32_exact(raw.dtype, lo, hi)
        want = np.clip((raw.astype(np.float64) - lo) / (hi - lo), 0.0, 1.0).astype(np.float32)
        got, used = normalise(raw, (float(lo), float(hi)), "where")
        assert got.dtype == np.float32 and used == (lo, hi)
        np.testing.assert_array_equal(got, want)
        assert np.array_equal(np.signbit(got), np.signbit(want))    # no -0.0 either


def test_normalise_keeps_float64_where_float32_is_not_exact():
    """Float data, 32-bit integers and fractional or huge ranges keep the float64 mapping (the
    float32 one could differ by more than float32's rounding there)."""
    from radiance_probes.io.volume import float32_exact
    rng = np.random.default_rng(4)
    cases = [(rng.normal(size=(3, 4, 5)).astype(np.float32), (-1.5, 2.25)),
             (rng.integers(0, 2 ** 30, (3, 4, 5)).astype(np.int32), (0.0, 2.0 ** 30)),
             (rng.integers(0, 2 ** 16, (3, 4, 5)).astype(np.uint16), (0.5, 1000.25)),
             (rng.integers(0, 2 ** 16, (3, 4, 5)).astype(np.uint16), (0.0, 2.0 ** 24))]
    for raw, (lo, hi) in cases:
        assert not float32_exact(raw.dtype, lo, hi)
        want = np.clip((raw.astype(np.float64) - lo) / (hi - lo), 0.0, 1.0).astype(np.float32)
        np.testing.assert_array_equal(normalise(raw, (lo, hi), "where")[0], want)
