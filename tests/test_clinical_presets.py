"""Clinical CT presets (app/scene/clinical_presets.py): each expands to a valid transfer function that
is its curve over Hounsfield units exactly, cut to the volume's window; the scene, the command
line and the viewer's state pick them; a CT opens with one; a CT window or preset on data that is
not in Hounsfield units is refused with a message that says so (it used to render an opaque box)."""
from __future__ import annotations

import argparse

import numpy as np
import pytest

from radiance_probes.scene.clinical_presets import (CLINICAL_PRESETS, check_hounsfield, expand,
                                                    hounsfield_problem, opening_scene)
from radiance_probes.frontend.option_types import OptionError
from radiance_probes.frontend.scene_options import apply_options, scene_from_arg
from radiance_probes.io.scene_file import (SceneError, TransferFunctionSpec, parse_scene,
                                           scene_to_dict)
from radiance_probes.scene.transfer import lookup, transfer_table
from radiance_probes.io.volume import VolumeError
from radiance_probes.io.load import load_scene_volume
from test_volume_formats import write_dicom_series


@pytest.mark.parametrize("name", list(CLINICAL_PRESETS))
@pytest.mark.parametrize("window", [None, (-160.0, 240.0), (-1024.0, 3071.0)])
def test_a_preset_is_its_hounsfield_curve_cut_to_the_window(name, window):
    p = CLINICAL_PRESETS[name]
    lo, hi = window or p.window
    colors, opacity = expand(name, (lo, hi))
    spec = TransferFunctionSpec(colors=colors, opacity=opacity, resolution=4096)
    table = transfer_table(spec)
    hu = np.linspace(lo, hi, 997)
    got = lookup(table, (hu - lo) / (hi - lo))
    pts = np.asarray(p.points)
    want = np.stack([np.interp(hu, pts[:, 0], pts[:, c]) for c in (1, 2, 3, 4)], axis=1)
    # the table's 4096 rows sample the piecewise-linear curve: exact at its points, within one
    # row's change between (float32 table)
    step = (hi - lo) / 4095
    slope = np.abs(np.diff(pts[:, 1:], axis=0) / np.maximum(np.diff(pts[:, :1], axis=0), 1e-9)).max()
    assert np.abs(got - want).max() <= slope * step + 1e-5, name
    # an atlas, not fog: somewhere opaque, somewhere clear, and colours that are not grey
    assert pts[:, 4].max() >= 0.9 and pts[:, 4].min() == 0.0
    assert np.ptp(pts[:, 1:4], axis=1).max() > 0.1


def test_the_scene_key_sets_the_window_and_round_trips():
    s = parse_scene({"volume": {"path": "ct.nii.gz"}, "transfer_function": {"preset": "ct_bone"}})
    lo, hi = CLINICAL_PRESETS["ct_bone"].window
    assert s.volume.domain == (lo, hi) and s.transfer_function.preset == "ct_bone"
    again = parse_scene(scene_to_dict(s))
    assert again == s and again.transfer_function.colors == s.transfer_function.colors
    # a window of the scene's own places the preset instead
    w = parse_scene({"volume": {"path": "ct.nii.gz", "window": "soft_tissue"},
                     "transfer_function": {"preset": "ct_bone"}})
    assert w.volume.window == (40.0, 400.0)
    assert w.transfer_function.colors != s.transfer_function.colors


@pytest.mark.parametrize("data, needle", [
    ({"transfer_function": {"preset": "ct_bone", "colormap": "grey"}},
     "transfer_function.preset: a clinical preset gives the colours"),
    ({"transfer_function": {"preset": "ct_knee"}}, "transfer_function.preset: expected one of"),
    ({"channels": [{"transfer_function": {"preset": "ct_bone"}}]},
     "channels[0].transfer_function.preset: clinical presets are for the scene's one"),
])
def test_bad_preset_keys_name_the_field(data, needle):
    with pytest.raises(SceneError) as err:
        parse_scene(data)
    assert needle in str(err.value)


def test_hounsfield_windows_and_presets_on_other_data_are_refused(tmp_path):
    """8-bit data, and data with no value below 0, are not Hounsfield units: a CT window or a
    clinical preset on them is an error that says so, not an opaque box."""
    u8 = tmp_path / "small_8x8x8_uint8.raw"
    (np.arange(512) % 256).astype(np.uint8).tofile(u8)
    pos = tmp_path / "pos.npy"
    np.save(pos, np.linspace(0, 4000, 512, dtype=np.float32).reshape(8, 8, 8))
    hu = tmp_path / "hu.npy"
    np.save(hu, np.linspace(-1024, 2000, 512, dtype=np.float32).reshape(8, 8, 8))
    for path, scene, needle in (
            (u8, {"volume": {"window": "bone"}}, "the CT window 'bone' is meant for Hounsfield "
                                                  "units, but its data is 8-bit"),
            (u8, {"transfer_function": {"preset": "ct_lung"}}, "the clinical preset 'ct_lung'"),
            (pos, {"volume": {"window": "lung"}}, "none below 0")):
        data = {**scene, "volume": {"path": str(path), **scene.get("volume", {})}}
        with pytest.raises(VolumeError) as err:
            load_scene_volume(parse_scene(data))
        assert needle in str(err.value) and "--data-window LEVEL,WIDTH" in str(err.value)
    # a window in the data's own numbers is not questioned, and HU data passes
    load_scene_volume(parse_scene({"volume": {"path": str(u8), "window": {"level": 100,
                                                                          "width": 50}}}))
    v = load_scene_volume(parse_scene({"volume": {"path": str(hu), "window": "bone"}}))
    assert hounsfield_problem(v) is None
    # a named window with no transfer function opens with its preset
    s = opening_scene(parse_scene({"volume": {"path": str(hu), "window": "bone"}}), v)
    assert s.transfer_function.preset == "ct_bone"


def test_a_rescale_gives_8_bit_data_its_units(tmp_path):
    """volume.rescale maps stored values to data units (value * slope + intercept, DICOM's rule):
    an 8-bit CT exported from the window [-1000, 1000] HU is Hounsfield units again, and the
    presets take it; the refusal without it names the key; DICOM, which carries its own, and a
    slope of 0 are refused."""
    u8 = tmp_path / "ct_8x8x8_uint8.raw"
    stored = (np.arange(512) % 256).astype(np.uint8)
    stored.tofile(u8)
    with pytest.raises(VolumeError) as err:
        load_scene_volume(parse_scene({"volume": {"path": str(u8)},
                                       "transfer_function": {"preset": "ct_bone"}}))
    assert "volume.rescale=SLOPE,INTERCEPT" in str(err.value)
    slope = 2000.0 / 255.0
    scene = parse_scene({"volume": {"path": str(u8), "rescale": [slope, -1000]},
                         "transfer_function": {"preset": "ct_bone"}})
    v = load_scene_volume(scene)
    assert hounsfield_problem(v) is None
    assert v.raw_min == pytest.approx(-1000.0) and v.raw_max == pytest.approx(1000.0, rel=1e-6)
    # a window in HU now lands where the stored values say: level 0, width 1000 -> stored 95.6..159.4
    w = load_scene_volume(parse_scene({"volume": {"path": str(u8), "rescale": [slope, -1000],
                                                  "window": {"level": 0, "width": 1000}}}))
    hu = stored.astype(np.float64) * slope - 1000.0
    want = np.clip((hu + 500.0) / 1000.0, 0.0, 1.0).reshape(8, 8, 8)
    np.testing.assert_allclose(np.asarray(w.data), want, atol=1e-5)
    with pytest.raises(SceneError, match="volume.rescale: the slope must not be 0"):
        parse_scene({"volume": {"path": str(u8), "rescale": [0, 5]}})
    folder = tmp_path / "dicom"
    write_dicom_series(folder, np.zeros((4, 6, 5), np.int16))
    with pytest.raises(VolumeError, match="carries its own RescaleSlope"):
        load_scene_volume(parse_scene({"volume": {"path": str(folder), "rescale": [1, 0]}}))


def test_a_dicom_ct_opens_with_a_ct_preset(tmp_path):
    folder = write_dicom_series(tmp_path / "ct", np.linspace(0, 3000, 3 * 6 * 6).astype(np.int16)
                                .reshape(3, 6, 6), slope=1.0, intercept=-1024.0)
    scene = scene_from_arg(str(folder))
    volume = load_scene_volume(scene)
    opened = opening_scene(scene, volume)
    assert opened.transfer_function.preset == "ct_bone"
    colors, opacity = expand("ct_bone", volume.value_range)
    assert opened.transfer_function.colors == colors and opened.transfer_function.opacity == opacity
    # a transfer function of the scene's own is kept
    own = scene.replace(transfer_function=TransferFunctionSpec(colormap="grey"))
    assert opening_scene(own, volume) is own
    # a builtin volume is no CT
    assert opening_scene(parse_scene({}), load_scene_volume(parse_scene({
        "volume": {"builtin": "cloud", "size": [8, 8, 8]}}))).transfer_function.preset is None


def test_the_command_line_option(tmp_path):
    scene = scene_from_arg(str(tmp_path / "ct.nii.gz"))
    out = apply_options(scene, argparse.Namespace(clinical_preset="ct_vessels"))
    assert out.transfer_function.preset == "ct_vessels"
    assert out.volume.domain == CLINICAL_PRESETS["ct_vessels"].window
    with pytest.raises(OptionError, match="--clinical-preset and --transfer-function"):
        apply_options(scene, argparse.Namespace(clinical_preset="ct_bone",
                                                transfer_function="tf.json"))



def test_the_render_help_names_the_presets(capsys):
    from radiance_probes.cli.main import main
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--clinical-preset" in text and all(name in text for name in CLINICAL_PRESETS)


def test_the_viewer_state_picks_a_preset_and_an_edit_drops_its_label():
    from radiance_probes.viewer.state import ViewerState
    scene = parse_scene({})
    state = ViewerState(scene, scene.camera)
    state.set_clinical_preset("ct_skin", (-1000.0, 1000.0))
    assert state.scene.transfer_function.preset == "ct_skin"
    state.set_transfer(opacity=((0.0, 0.0), (1.0, 1.0)))
    assert state.scene.transfer_function.preset is None
    assert state.scene.transfer_function.colors is not None   # the colours stay


def test_check_needs_no_file_for_a_window_of_its_own():
    class V:
        name, raw_dtype, raw_min, raw_max, dicom_series = "v", "uint8", 0.0, 255.0, None
    spec = parse_scene({"volume": {"window": {"level": 0, "width": 10}}}).volume
    check_hounsfield(spec, None, V())   # not a named CT window, no preset: nothing to say
