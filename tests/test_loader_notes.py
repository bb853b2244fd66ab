"""Nothing read silently wrong: a plain multi-page TIFF whose page count 3 or 4 divides is read as z
slices with a note that says so and how to read its pages as channels (--axes c3zyx, which splits
the unnamed page axis); a volume with a time axis names it in a note (its steps, the one shown,
--time)."""
from __future__ import annotations

import nibabel as nib
import numpy as np
import pytest
import tifffile
import zarr

from radiance_probes.cli.main import build_parser, main
from radiance_probes.frontend.scene_options import apply_options, scene_from_arg
from radiance_probes.io.scene_file import SceneError, VolumeSpec, parse_scene
from radiance_probes.io.volume import VolumeError
from radiance_probes.io.load import load_scene_volume, load_volume

CELLS = np.random.default_rng(7).random((3, 8, 6, 5)).astype(np.float32)   # [c, z, y, x]


def scene_of(*argv: str):
    args = build_parser().parse_args(["render", *argv])
    return apply_options(scene_from_arg(args.scene), args)


def test_a_plain_page_stack_of_3k_pages_says_how_it_was_read_and_how_else(tmp_path):
    path = tmp_path / "cells.tif"
    tifffile.imwrite(path, CELLS, metadata=None)       # 24 pages, no axes
    v = load_scene_volume(scene_of(str(path)))
    assert v.dims == (5, 6, 24) and v.channel_count == 1
    (note,) = v.notes
    assert "24 pages carry no axes metadata and were read as 24 z slices" in note
    assert "--axes c3zyx (3 channels of 8 slices) or c4zyx (4 channels of 6 slices)" in note
    assert "--set volume.axes=c3zyx" in note
    # read as the note says: the channels as written
    v = load_scene_volume(scene_of(str(path), "--axes", "c3zyx"))
    assert v.dims == (5, 6, 8) and v.channel_count == 3 and v.notes == ()
    for c in range(3):
        lo, hi = v.channel_ranges[c]
        np.testing.assert_allclose(v.channel(c), (CELLS[c] - lo) / (hi - lo), atol=1e-6)
    # the same through --set, and the count may sit on the other split axis
    same = load_scene_volume(scene_of(str(path), "--set", "volume.axes=cz8yx"))
    np.testing.assert_array_equal(same.data, v.data)


def test_channels_that_alternate_page_by_page_read_with_the_count_after_z(tmp_path):
    path = tmp_path / "interleaved.tif"
    tifffile.imwrite(path, np.ascontiguousarray(CELLS.transpose(1, 0, 2, 3)), metadata=None,
                     photometric="minisblack")
    v = load_volume(VolumeSpec(path=str(path), builtin=None, axes="zc3yx"))
    assert v.channel_count == 3 and v.dims == (5, 6, 8)
    lo, hi = v.channel_ranges[1]
    np.testing.assert_allclose(v.channel(1), (CELLS[1] - lo) / (hi - lo), atol=1e-6)


@pytest.mark.parametrize("pages, counts", [(7, ()), (12, (3, 4)), (16, (4,)), (4, ())])
def test_the_note_only_where_a_channel_count_divides_the_pages(pages, counts, tmp_path):
    path = tmp_path / "stack.tif"
    tifffile.imwrite(path, np.arange(pages * 4 * 5, dtype=np.uint16).reshape(pages, 4, 5),
                     metadata=None, photometric="minisblack")
    notes = load_volume(VolumeSpec(path=str(path), builtin=None)).notes
    assert [f"c{c}zyx" in " ".join(notes) for c in (3, 4)] == [c in counts for c in (3, 4)]
    assert bool(notes) == bool(counts)


def test_a_tiff_that_names_its_axes_gets_no_note(tmp_path):
    path = tmp_path / "named.tif"
    tifffile.imwrite(path, CELLS[0], metadata={"axes": "ZYX"})
    assert load_volume(VolumeSpec(path=str(path), builtin=None)).notes == ()


@pytest.mark.parametrize("axes, needle", [
    ("czyx", r"splits the 24 pages into c, z: count all of them but one.*e\.g\. c3zyx"),
    ("c5zyx", "the counts dividing 24"),
    ("c3z4yx", "count all of them but one"),
    ("c3zy2x", "counts y, which is not among the axes the pages split into"),
])
def test_counts_that_do_not_split_the_pages_are_refused_naming_the_flag(axes, needle, tmp_path):
    path = tmp_path / "cells.tif"
    tifffile.imwrite(path, CELLS, metadata=None)
    with pytest.raises(VolumeError, match=needle) as err:
        load_volume(VolumeSpec(path=str(path), builtin=None, axes=axes))
    assert "--axes" in str(err.value)


def test_counts_elsewhere_are_refused(tmp_path):
    np.save(tmp_path / "a.npy", CELLS)
    with pytest.raises(VolumeError, match="nothing to split"):
        load_volume(VolumeSpec(path=str(tmp_path / "a.npy"), builtin=None, axes="c3zyx"))
    with pytest.raises(SceneError, match="volume.axes"):
        parse_scene({"volume": {"path": "a.npy", "axes": "c0zyx"}})
    with pytest.raises(SceneError, match="volume.axes"):
        parse_scene({"volume": {"path": "a.npy", "axes": "c-zyx"}})


# ---- time axes -------------------------------------------------------------------------------------

def _nifti_4d(path):
    data = np.random.default_rng(2).random((6, 5, 4, 3)).astype(np.float32)   # [i, j, k, t]
    nib.save(nib.Nifti1Image(data, np.eye(4)), str(path))
    return path


def test_a_4d_nifti_names_its_time_axis_in_a_note(tmp_path):
    path = _nifti_4d(tmp_path / "bold.nii.gz")
    for time in (0, 2):
        v = load_scene_volume(scene_of(str(path), "--time", str(time)))
        assert v.time_steps == 3
        assert any(f"a time series of 3 steps; showing step {time}" in n and "--time N" in n
                   and "0 to 2" in n for n in v.notes), v.notes


def test_a_bricked_zarr_time_series_names_its_time_axis(tmp_path):
    data = np.random.default_rng(1).random((2, 8, 8, 8)).astype(np.float32)
    z = zarr.create_array(str(tmp_path / "t.zarr"), shape=data.shape, dtype=data.dtype,
                          dimension_names=["t", "z", "y", "x"])
    z[...] = data
    v = load_volume(VolumeSpec(path=str(tmp_path / "t.zarr"), builtin=None), time=1, brick=8)
    assert any("a time series of 2 steps; showing step 1" in n for n in v.notes), v.notes


def test_the_command_line_prints_the_notes(tmp_path, capsys, monkeypatch):
    """render prints each note before the GPU starts (here, refused: no GL in this test)."""
    import radiance_probes.gl.context as context

    def no_gl(*_a, **_k):
        raise context.ContextError("no OpenGL in this test")
    monkeypatch.setattr(context, "create_headless_context", no_gl)
    tif = tmp_path / "cells.tif"
    tifffile.imwrite(tif, CELLS, metadata=None)
    for path in (tif, _nifti_4d(tmp_path / "bold.nii.gz")):
        assert main(["render", str(path), "--out", str(tmp_path / "x.png")]) == 2
        err = capsys.readouterr().err
        assert "no OpenGL in this test" in err
        assert ("note: cells.tif: its 24 pages" in err if path == tif else
                "note: bold.nii.gz is a time series of 3 steps; showing step 0" in err), err
