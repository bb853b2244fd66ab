"""The viewer's messages on opening a file say the path once: "could not open X: why", not
"could not open X: X: why" (a loader's error starts with the path it failed on)."""
from __future__ import annotations

import numpy as np
import pytest

from radiance_probes.viewer.files import scene_for_path
from radiance_probes.viewer.viewer import could_not_open
from radiance_probes.io.volume import VolumeError
from radiance_probes.io.load import load_scene_volume
from radiance_probes.io.scene_file import default_scene


@pytest.mark.parametrize("given", ["relative", "absolute", "home"])
def test_could_not_open_says_the_path_once(given, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HOME", str(tmp_path))
    np.arange(60, dtype=np.uint16).tofile(tmp_path / "scan.raw")
    path = {"relative": "scan.raw", "absolute": str(tmp_path / "scan.raw"),
            "home": "~/scan.raw"}[given]
    with pytest.raises(VolumeError) as err:
        scene, _ = scene_for_path(path, default_scene())   # resolves the path, as the viewer does
        load_scene_volume(scene)
    assert str(err.value).startswith(str(tmp_path / "scan.raw") + ":")   # the loader's own words
    message = could_not_open(path, err.value)
    assert message.startswith(f"could not open {path}: cannot tell the dimensions"), message
    assert message.count("scan.raw") == 1 and "--dims" in message   # the path once, the hint kept


def test_an_error_about_another_file_keeps_its_path(tmp_path):
    err = VolumeError(f"{tmp_path / 'other.nii'}: cannot read NIfTI")
    assert could_not_open(tmp_path / "scene.json", err) == (
        f"could not open {tmp_path / 'scene.json'}: {tmp_path / 'other.nii'}: cannot read NIfTI")
