"""Fuzzed volume loaders (hypothesis): random and mutated `.raw` names and sizes, NRRD headers,
`.npy` headers, and mutated NIfTI, TIFF and DICOM files that nibabel, tifffile and pydicom wrote. Whatever the file, load_volume returns a valid Volume or raises VolumeError, the
loaders' own error: never another exception, a crash or a hang (each example runs under a
watchdog, and hypothesis's deadline flags slow ones).

Budget: a bounded number of examples per test (a few seconds each on two cores), derandomised so
CI runs the same examples every time; a failure prints the file that caused it."""
from __future__ import annotations

import contextlib
import io
import signal
import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from radiance_probes.io.scene_file import VolumeSpec
from radiance_probes.io.volume_files import RAW_DTYPES
from radiance_probes.io.volume import Volume, VolumeError
from radiance_probes.io.load import load_volume

FUZZ = settings(max_examples=400, deadline=2000, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])
WATCHDOG_SECONDS = 10


@contextlib.contextmanager
def watchdog(seconds: int = WATCHDOG_SECONDS):
    """Fails the example instead of hanging the test run."""
    def fire(*_):
        raise TimeoutError(f"the loader ran for more than {seconds} s")
    old = signal.signal(signal.SIGALRM, fire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def load_or_volume_error(path: Path, **spec) -> Volume | None:
    """The one contract: a usable Volume, or VolumeError. Anything else fails the test."""
    with watchdog():
        try:
            volume = load_volume(VolumeSpec(path=str(path), builtin=None, **spec))
        except VolumeError as exc:
            assert str(exc).strip() and "\n" not in str(exc).strip(), repr(exc)
            return None
    data = volume.data
    assert data.dtype == np.float32 and data.ndim == 3 and min(data.shape) >= 1
    assert np.isfinite(data).all() and data.min() >= 0.0 and data.max() <= 1.0
    assert all(np.isfinite(s) and s > 0 for s in volume.spacing)
    return volume


# ---- .raw: names and sizes ----------------------------------------------------------------------

dims_text = st.one_of(st.integers(0, 6).map(str), st.integers(-3, 10**20).map(str),
                      st.sampled_from(["", "x", "1e3", "٣", "0x4", " 2"]))
dtype_text = st.one_of(st.sampled_from(sorted(RAW_DTYPES)),
                       st.sampled_from(["UINT8", "float16", "int64", "uint", "float", "u8", ""]),
                       st.text("abcfilntu0123468", max_size=8))
raw_names = st.builds(lambda stem, x, y, z, t, tail: f"{stem}_{x}x{y}x{z}_{t}{tail}",
                      st.sampled_from(["vol", "a_b", "x_1x1x1_uint8", ""]), dims_text, dims_text,
                      dims_text, dtype_text, st.sampled_from([".raw", ".RAW", ".raw.raw"]))


@FUZZ
@given(name=raw_names, size=st.integers(0, 300), fill=st.integers(0, 255))
def test_raw_names_and_sizes(tmp_path_factory, name, size, fill):
    folder = tmp_path_factory.mktemp("raw")
    p = folder / name
    try:
        p.write_bytes(bytes([fill]) * size)
    except OSError:  # a name the file system refuses is not the loader's business
        return
    load_or_volume_error(p)


@FUZZ
@given(dims=st.tuples(*[st.integers(-2, 2**40)] * 3), dtype=st.sampled_from(sorted(RAW_DTYPES)),
       size=st.integers(0, 200))
def test_raw_with_dims_and_dtype_from_the_scene(tmp_path_factory, dims, dtype, size):
    """volume.dims/dtype given by the scene (parse_scene bounds them; load_volume must not rely on
    that), over files of any size."""
    p = tmp_path_factory.mktemp("raw") / "plain.raw"
    p.write_bytes(np.arange(size, dtype=np.uint8).tobytes())
    load_or_volume_error(p, dims=dims, dtype=dtype)


def test_raw_products_beyond_64_bits_do_not_wrap(tmp_path):
    """2^22 x 2^21 x 2^21 voxels of 8 bytes is 2^67 bytes: in int64 it wraps to 0 and would
    match an empty file, then fail inside NumPy's reshape."""
    p = tmp_path / f"v_{2**22}x{2**21}x{2**21}_float64.raw"
    p.write_bytes(b"")
    with pytest.raises(VolumeError, match="bytes"):
        load_volume(VolumeSpec(path=str(p), builtin=None))


# ---- NRRD headers ------------------------------------------------------------------------------

NRRD_TYPES = ["uint8", "int16", "uint16", "float", "double", "int64", "block", "signed char",
              "complex", "", "uchar"]
ENCODINGS = ["raw", "gzip", "ascii", "text", "bzip2", "hex", "bogus", ""]
number_text = st.one_of(st.integers(-5, 9).map(str), st.sampled_from(
    ["nan", "inf", "-0", "1e309", "0.5", "NaN", "", "(1,0,0)", "none"]))


def nrrd_header(magic, kind, dimension, sizes, encoding, extra) -> bytes:
    lines = [magic, f"type: {kind}", f"dimension: {dimension}", "sizes: " + " ".join(sizes),
             f"encoding: {encoding}", *extra]
    return ("\n".join(lines) + "\n\n").encode("utf-8", "surrogatepass")


extra_fields = st.lists(st.one_of(
    st.builds(lambda v: "spacings: " + " ".join(v), st.lists(number_text, max_size=4)),
    st.builds(lambda v: "space directions: " + " ".join(v), st.lists(
        st.one_of(st.just("none"), st.builds(lambda a, b, c: f"({a},{b},{c})", number_text,
                                             number_text, number_text)), max_size=4)),
    st.builds(lambda v: f"space dimension: {v}", number_text),
    st.sampled_from(["endian: big", "endian: little", "endian: middle", "space: RAS",
                     "line skip: 3", "byte skip: -1", "byte skip: 99999", "data file: nowhere.raw",
                     "kinds: domain domain domain", "# comment", "content: ∆", "garbage"])),
    max_size=4)


@FUZZ
@given(magic=st.sampled_from(["NRRD0004", "NRRD0005", "NRRD0001", "NRRD", "NRRD9999", "PNG"]),
       kind=st.sampled_from(NRRD_TYPES), dimension=number_text,
       sizes=st.lists(number_text, max_size=4), encoding=st.sampled_from(ENCODINGS),
       extra=extra_fields, body=st.binary(max_size=128))
def test_nrrd_headers(tmp_path_factory, magic, kind, dimension, sizes, encoding, extra, body):
    p = tmp_path_factory.mktemp("nrrd") / "v.nrrd"
    p.write_bytes(nrrd_header(magic, kind, dimension, sizes, encoding, extra) + body)
    load_or_volume_error(p)


def valid_nrrd(tmp_path: Path) -> bytes:
    import nrrd
    p = tmp_path / "valid.nrrd"
    nrrd.write(str(p), np.arange(24, dtype=np.uint8).reshape(2, 3, 4),
               {"spacings": [1.0, 2.0, 0.5]}, index_order="C")
    return p.read_bytes()


def mutate(data: bytes, edits) -> bytes:
    b = bytearray(data)
    for position, kind, value in edits:
        i = position % (len(b) + 1)
        if kind == "flip" and i < len(b):
            b[i] ^= value
        elif kind == "insert":
            b[i:i] = bytes([value])
        elif kind == "delete":
            del b[i:i + 1 + value % 8]
    return bytes(b)


mutations = st.lists(st.tuples(st.integers(0, 400), st.sampled_from(["flip", "insert", "delete"]),
                               st.integers(1, 255)), min_size=1, max_size=6)


@FUZZ
@given(edits=mutations)
def test_mutated_nrrd(tmp_path_factory, edits):
    folder = tmp_path_factory.mktemp("nrrd")
    p = folder / "m.nrrd"
    p.write_bytes(mutate(valid_nrrd(folder), edits))
    load_or_volume_error(p)


# ---- .npy headers -------------------------------------------------------------------------------

descrs = st.one_of(st.sampled_from(["<u1", "|u1", "<i2", ">u2", "<f4", ">f8", "<f2", "<i8", "|b1",
                                    "<c8", "|V4", "<M8[s]", "|O", "<U3", "|S2", "[('a', '<f4')]",
                                    "<f16", "bogus", "<u0"]),
                   st.text(max_size=6).map(repr))
shape_text = st.one_of(
    st.lists(st.integers(-2, 2**40), max_size=5).map(lambda v: repr(tuple(v))),
    st.sampled_from(["()", "(3,", "None", "[2, 2, 2]", "(2.0, 2, 2)", "(1, 1, 1)", "'abc'"]))


def npy_bytes(major, descr, fortran, shape, body, pad) -> bytes:
    header = f"{{'descr': {descr}, 'fortran_order': {fortran}, 'shape': {shape}, }}"
    header = header + " " * pad + "\n"
    raw = header.encode("latin1", "replace")
    length = struct.pack("<H" if major == 1 else "<I", len(raw))
    return b"\x93NUMPY" + bytes([major, 0]) + length + raw + body


@pytest.mark.filterwarnings("ignore:Data type alias:DeprecationWarning")  # NumPy on 'a' descrs
@FUZZ
@given(major=st.sampled_from([1, 2, 3]), descr=descrs,
       fortran=st.sampled_from(["False", "True", "0", "'no'", "None"]), shape=shape_text,
       body=st.binary(max_size=200), pad=st.integers(0, 70))
def test_npy_headers(tmp_path_factory, major, descr, fortran, shape, body, pad):
    p = tmp_path_factory.mktemp("npy") / "v.npy"
    p.write_bytes(npy_bytes(major, descr if descr.startswith(("'", "[", '"')) else repr(descr),
                            fortran, shape, body, pad))
    load_or_volume_error(p)


@FUZZ
@given(edits=mutations, dtype=st.sampled_from(["<u1", "<f4", ">i2", "<f8"]))
def test_mutated_npy(tmp_path_factory, edits, dtype):
    buf = io.BytesIO()
    data = np.linspace(0, 1, 27).reshape(3, 3, 3)
    if dtype == "<f4" or dtype == "<f8":
        data = data.astype(dtype)
    else:
        data = (data * 100).astype(dtype)
    np.save(buf, data)
    p = tmp_path_factory.mktemp("npy") / "m.npy"
    p.write_bytes(mutate(buf.getvalue(), edits))
    load_or_volume_error(p)


# ---- NIfTI, TIFF, DICOM: mutated files the libraries wrote ---------------------------------------
# Fewer examples than above: each reads through a library (nibabel, tifffile, pydicom), and the
# mutations of their headers are what matters; together they stay within a few seconds.

FUZZ_FORMATS = settings(FUZZ, max_examples=60)
NEW_FORMAT_ARRAY = (np.arange(2 * 3 * 4, dtype=np.int16).reshape(2, 3, 4) * 50 - 400)


def valid_nifti(folder: Path, name: str) -> bytes:
    import nibabel as nib
    img = nib.Nifti1Image(np.ascontiguousarray(NEW_FORMAT_ARRAY.transpose(2, 1, 0)), np.eye(4))
    img.header.set_zooms((0.5, 0.5, 2.0))
    img.header.set_slope_inter(2.0, -1024.0)
    nib.save(img, str(folder / name))
    return (folder / name).read_bytes()


@FUZZ_FORMATS
@given(edits=mutations, name=st.sampled_from(["v.nii", "v.nii.gz"]))
def test_mutated_nifti(tmp_path_factory, edits, name):
    folder = tmp_path_factory.mktemp("nii")
    p = folder / name
    p.write_bytes(mutate(valid_nifti(folder, name), edits))
    load_or_volume_error(p)


@FUZZ_FORMATS
@given(edits=mutations, dtype=st.sampled_from(["uint8", "uint16", "float32"]))
def test_mutated_tiff(tmp_path_factory, edits, dtype):
    import tifffile
    folder = tmp_path_factory.mktemp("tif")
    p = folder / "v.tif"
    tifffile.imwrite(p, NEW_FORMAT_ARRAY.astype(dtype), photometric="minisblack")
    p.write_bytes(mutate(p.read_bytes(), edits))
    load_or_volume_error(p)


@pytest.mark.filterwarnings("ignore::UserWarning")   # pydicom warns on each mangled value it reads
@FUZZ_FORMATS
@given(edits=mutations, which=st.integers(0, 1))
def test_mutated_dicom_series(tmp_path_factory, edits, which):
    """A two-slice CT series with one slice's bytes mutated (header or pixels)."""
    from test_volume_formats import write_dicom_series
    folder = tmp_path_factory.mktemp("dcm") / "series"
    write_dicom_series(folder, NEW_FORMAT_ARRAY, slope=1.0, intercept=-1024.0, uid="1.2.3")
    f = sorted(folder.iterdir())[which]
    f.write_bytes(mutate(f.read_bytes(), [(p + 128, k, v) for p, k, v in edits]))
    load_or_volume_error(folder)
