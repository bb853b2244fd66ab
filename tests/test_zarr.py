"""Zarr and OME-Zarr stores: axes as the store names them (OME-Zarr's multiscales axes, version
3's dimension_names, xarray's _ARRAY_DIMENSIONS), channels and time steps read through them, the
finest level of an OME-Zarr image with its scale as the spacing; unnamed axes and groups without
an image refused with the problem named."""
from __future__ import annotations

import numpy as np
import pytest

zarr = pytest.importorskip("zarr")

from radiance_probes.io.scene_file import parse_scene  # noqa: E402
from radiance_probes.scene.types import VolumeError  # noqa: E402
from radiance_probes.io.load import load_scene_volume  # noqa: E402

DATA = (np.arange(2 * 3 * 4 * 5 * 6) % 251).reshape(2, 3, 4, 5, 6).astype(np.uint16)  # t c z y x


def _load(path, **scene):
    return load_scene_volume(parse_scene({"volume": {"path": str(path),
                                                     **scene.pop("volume", {})}, **scene}))


def _ome(path, data, axes, scale, version="0.4"):
    fmt = 2 if version == "0.4" else 3
    g = zarr.open_group(str(path), mode="w", zarr_format=fmt)
    kinds = {"t": "time", "c": "channel"}
    image = {"version": version,
             "axes": [{"name": a, "type": kinds.get(a, "space")} for a in axes],
             "datasets": [{"path": "0", "coordinateTransformations":
                           [{"type": "scale", "scale": list(scale)}]},
                          {"path": "1", "coordinateTransformations":
                           [{"type": "scale", "scale": [s * 2 for s in scale]}]}]}
    if version == "0.4":
        g.attrs["multiscales"] = [image]
    else:
        g.attrs["ome"] = {"version": version, "multiscales": [image]}
    g.create_array("0", shape=data.shape, dtype=data.dtype)[...] = data
    coarse = data[..., ::2, ::2, ::2]
    g.create_array("1", shape=coarse.shape, dtype=data.dtype)[...] = coarse


def _expected(c, t=0):
    d = DATA[:, c].astype(np.float64)
    lo, hi = d.min(), d.max()          # a series: its whole range (SPEC.md, Time series)
    return (d[t] - lo) / (hi - lo)


@pytest.mark.parametrize("version", ["0.4", "0.5"])
def test_ome_zarr_channels_time_and_spacing(tmp_path, version):
    _ome(tmp_path / "img.zarr", DATA, "tczyx", (1.0, 1.0, 2.0, 0.5, 0.25), version)
    v = _load(tmp_path / "img.zarr", time=1)
    assert (v.dims, v.channel_count, v.time, v.time_steps) == ((6, 5, 4), 3, 1, 2)
    assert v.spacing == (0.25, 0.5, 2.0)                      # x, y, z from the finest level
    for c in range(3):
        np.testing.assert_allclose(v.channel(c), _expected(c, 1), atol=1e-6)
    # the scene's spacing wins; a channel chosen
    v = _load(tmp_path / "img.zarr", volume={"spacing": [1, 1, 1]}, channels=[{"index": 2}])
    assert v.spacing == (1.0, 1.0, 1.0) and v.channel_count == 1
    np.testing.assert_allclose(v.data, _expected(2, 0), atol=1e-6)


def test_zarr_arrays_name_their_axes_or_are_refused(tmp_path):
    a = zarr.create_array(str(tmp_path / "v3.zarr"), shape=DATA.shape[1:], dtype=DATA.dtype,
                          dimension_names=["c", "z", "y", "x"])
    a[...] = DATA[0]
    assert _load(tmp_path / "v3.zarr").channel_count == 3
    b = zarr.create_array(str(tmp_path / "v2.zarr"), shape=(4, 3, 5, 6), dtype=DATA.dtype,
                          zarr_format=2, attributes={"_ARRAY_DIMENSIONS": ["z", "c", "y", "x"]})
    b[...] = np.ascontiguousarray(DATA[0].transpose(1, 0, 2, 3))
    v = _load(tmp_path / "v2.zarr")
    np.testing.assert_allclose(v.channel(1), (DATA[0, 1] - DATA[0, 1].min())
                               / np.ptp(DATA[0, 1].astype(np.float64)), atol=1e-6)
    n = zarr.create_array(str(tmp_path / "plain.zarr"), shape=DATA.shape[1:], dtype=DATA.dtype)
    n[...] = DATA[0]
    with pytest.raises(VolumeError, match=r"plain\.zarr: a 4D array .* give volume\.axes"):
        _load(tmp_path / "plain.zarr")
    assert _load(tmp_path / "plain.zarr", volume={"axes": "czyx"}).channel_count == 3
    with pytest.raises(VolumeError, match="disagrees with the file's own axes"):
        _load(tmp_path / "v3.zarr", volume={"axes": "tzyx"})
    g = zarr.open_group(str(tmp_path / "group.zarr"), mode="w")
    g.create_array("raw", shape=(2, 2, 2), dtype="uint8")
    with pytest.raises(VolumeError, match="without OME-Zarr multiscales metadata; give the path "
                                          "of one of its arrays \\(raw\\)"):
        _load(tmp_path / "group.zarr")
    (tmp_path / "broken.zarr").mkdir()
    (tmp_path / "broken.zarr" / "zarr.json").write_text("{not json")
    with pytest.raises(VolumeError, match="broken.zarr: cannot read Zarr"):
        _load(tmp_path / "broken.zarr")
