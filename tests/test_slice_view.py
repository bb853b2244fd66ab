"""The slice view (app/viewer/slice_view.py, slice_panel.py): its maths on an asymmetric volume
(every voxel's value says which voxel it is, and a block sits in one corner), then the real viewer
on a private Xvfb with the slices on: the value under the mouse, the crop drawn where the crop box
is, a click moving the slices and the orbit's centre, the wheel stepping a slice."""
from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from radiance_probes.scene.clip_region import clip_region
from radiance_probes.io.scene_file import CameraSpec, parse_scene
from radiance_probes.twins.camera import camera_frame
from radiance_probes.viewer import layout, orbit
from radiance_probes.viewer import slice_view as sv
from radiance_probes.io.load import volume_from_array
from viewer_harness import dump, png, view, write_script

NX, NY, NZ = 20, 16, 12            # voxels along x, y, z: the world box is 1 x 0.8 x 0.6
HALF = np.array([0.5, 0.4, 0.3])
LOW, HIGH = -2000.0, 10000.0       # the value range the volume is normalised by


def raw_value(i: int, j: int, k: int) -> int:
    """The asymmetric volume's value at voxel (i, j, k): its index, less 2000, plus 8000 in the
    block at high x, low y, high z."""
    block = i >= 13 and j < 5 and k >= 8
    return i + NX * j + NX * NY * k - 2000 + 8000 * block


def asymmetric_raw() -> np.ndarray:
    k, j, i = np.meshgrid(np.arange(NZ), np.arange(NY), np.arange(NX), indexing="ij")
    block = (i >= 13) & (j < 5) & (k >= 8)
    return (i + NX * j + NX * NY * k - 2000 + 8000 * block).astype(np.int16)


def asymmetric_volume(value_range=(LOW, HIGH)):
    return volume_from_array(asymmetric_raw(), value_range=value_range, name="asym")


def voxel_of(raw: float) -> tuple[int, int, int]:
    """Which voxel holds a value of the asymmetric volume (the block's 8000 taken off)."""
    index = int(raw) + 2000
    index -= 8000 if index >= NX * NY * NZ else 0
    return index % NX, (index // NX) % NY, index // (NX * NY)


def centre(i: int, n: int, half: float) -> float:
    return ((i + 0.5) / n * 2 - 1) * half


# ---- slice index <-> world position ---------------------------------------------------------------

def test_slice_index_and_world_position():
    assert sv.slice_coord(0, NX, 0.5) == pytest.approx(-0.475)
    assert sv.slice_coord(NX - 1, NX, 0.5) == pytest.approx(0.475)
    for i in range(NX):
        assert sv.slice_index(sv.slice_coord(i, NX, 0.5), NX, 0.5) == i
    # voxel 4 ends and voxel 5 starts at -0.5 + 5 * 0.05 = -0.25
    assert sv.slice_index(-0.25 - 1e-9, NX, 0.5) == 4
    assert sv.slice_index(-0.25 + 1e-9, NX, 0.5) == 5
    assert sv.slice_index(-7.0, NX, 0.5) == 0 and sv.slice_index(7.0, NX, 0.5) == NX - 1
    assert sv.slice_indices((0.0, 0.0, 0.0), (NX, NY, NZ), HALF) == (10, 8, 6)
    volume = asymmetric_volume()
    np.testing.assert_allclose(volume.half_extent, HALF)


# ---- the slices' orientation --------------------------------------------------------------------

def test_each_slice_shows_the_voxels_its_screen_axes_say():
    raw = asymmetric_raw()
    z = sv.slice_image(raw, 2, 6)          # right +x, up +y
    assert z.shape == (NY, NX)
    assert voxel_of(z[0, 0]) == (0, NY - 1, 6) and voxel_of(z[-1, -1]) == (NX - 1, 0, 6)
    assert voxel_of(z[3, 7]) == (7, NY - 1 - 3, 6)
    x = sv.slice_image(raw, 0, 10)         # right -z, up +y
    assert x.shape == (NY, NZ)
    assert voxel_of(x[0, 0]) == (10, NY - 1, NZ - 1) and voxel_of(x[-1, -1]) == (10, 0, 0)
    assert voxel_of(x[2, 5]) == (10, NY - 1 - 2, NZ - 1 - 5)
    y = sv.slice_image(raw, 1, 3)          # right +x, up +z
    assert y.shape == (NZ, NX)
    assert voxel_of(y[0, 0]) == (0, 3, NZ - 1) and voxel_of(y[-1, -1]) == (NX - 1, 3, 0)
    assert voxel_of(y[4, 9]) == (9, 3, NZ - 1 - 4)


@pytest.mark.parametrize("axis, drag", [(2, (0.0, 0.0)), (0, (-225.0, 0.0)), (1, (0.0, -225.0))])
def test_a_slice_looks_as_the_3d_view_orbited_to_face_it(axis, drag):
    """The slice's texels, placed at their voxels' world centres and projected by the 3D view's
    camera orbited from the default one to face the slice (z: as it is; x: a quarter turn to the
    left, the eye on +x; y: tilted under the volume), run left to right along the image's columns
    and top to bottom along its rows: the slice shows the data as the 3D view does."""
    raw = asymmetric_raw()
    dims = (NX, NY, NZ)
    index = {0: 4, 1: 11, 2: 9}[axis]      # the block's corner shows in the y and z slices
    image = sv.slice_image(raw, axis, index)
    cam = orbit.orbit(CameraSpec(eye=(0.0, 0.0, 2.2)), *drag)
    forward = np.subtract(cam.target, cam.eye)
    assert abs(forward[axis]) / np.linalg.norm(forward) > 0.99      # it faces the slice
    voxels = np.vectorize(voxel_of, otypes=[int, int, int])(image)
    points = np.stack([np.vectorize(lambda v, a=a: centre(v, dims[a], HALF[a]))(voxels[a])
                       for a in range(3)], axis=-1)
    frame = camera_frame(cam, 400, 400)
    pixels = orbit.project(orbit.view_projection(frame), points, 400, 400)
    assert (np.diff(pixels[..., 0], axis=1) > 0).all()      # columns: left to right on screen
    assert (np.diff(pixels[..., 1], axis=0) > 0).all()      # rows: top to bottom on screen
    np.testing.assert_allclose(sv.slice_world_points(axis, index, dims, HALF), points, atol=1e-12)


def test_the_block_shows_in_its_corner():
    """The block (high x, low y, high z) seen in each slice: the bright texels where the screen
    axes put them."""
    raw = asymmetric_raw()
    bright = lambda im: im > 4000      # noqa: E731
    z = bright(sv.slice_image(raw, 2, 9))
    assert z[NY - 5:, 13:].all() and z.sum() == 5 * 7          # bottom right
    y = bright(sv.slice_image(raw, 1, 2))
    assert y[:NZ - 8, 13:].all() and y.sum() == 4 * 7          # top right
    x = bright(sv.slice_image(raw, 0, 15))
    assert x[NY - 5:, :NZ - 8].all() and x.sum() == 5 * 4      # bottom left (+z is on the left)


# ---- mouse pixel -> voxel -> value ----------------------------------------------------------------

def test_the_value_under_a_pixel_is_the_voxel_drawn_there():
    volume = asymmetric_volume()
    dims = volume.dims
    rect = (100.0, 50.0, 200.0, 160.0)     # the z slice, 10 px a voxel
    pixel = (100 + 4.5 * 10, 50 + 3.5 * 10)  # column 4, row 3
    voxel = sv.pixel_voxel(pixel, rect, 2, 7, dims)
    assert voxel == (4, NY - 1 - 3, 7)
    assert sv.data_value(volume, voxel) == (raw_value(4, 12, 7), 0)
    assert sv.describe_voxel(volume, voxel) == f"(4, 12, 7): {raw_value(4, 12, 7)}"
    assert sv.pixel_voxel((99.9, 60.0), rect, 2, 7, dims) is None
    assert sv.pixel_voxel((300.0, 60.0), rect, 2, 7, dims) is None   # the right edge is outside
    assert sv.pixel_voxel((299.9, 209.9), rect, 2, 7, dims) == (NX - 1, 0, 7)
    # the x slice: column c is z = NZ - 1 - c
    rect_x = (0.0, 0.0, 120.0, 160.0)
    voxel = sv.pixel_voxel((2.5 * 10, 13.5 * 10), rect_x, 0, 10, dims)
    assert voxel == (10, NY - 1 - 13, NZ - 1 - 2)
    assert sv.data_value(volume, voxel)[0] == raw_value(10, 2, 9)
    # the block's voxels, far above the rest
    assert sv.data_value(volume, (16, 3, 9)) == (raw_value(16, 3, 9), 0)
    assert raw_value(16, 3, 9) == 8956


def test_pixel_and_world_map_both_ways():
    rect = (10.0, 20.0, 120.0, 160.0)
    for axis in range(3):
        p = np.array([0.31, -0.17, 0.12])
        (px, py), = sv.world_pixels([p], rect, axis, HALF)
        back = sv.pixel_world((px, py), rect, axis, p[axis], HALF)
        np.testing.assert_allclose(back, p, atol=1e-12)
    # the centre of voxel (i, j) of the z slice lands at the centre of its texel
    (px, py), = sv.world_pixels([[centre(4, NX, 0.5), centre(12, NY, 0.4), 0.0]],
                                (100.0, 50.0, 200.0, 160.0), 2, HALF)
    assert (px, py) == pytest.approx((100 + 4.5 * 10, 50 + 3.5 * 10))


def test_values_beyond_the_window_and_units():
    narrow = asymmetric_volume((-100.0, 100.0))
    assert sv.data_value(narrow, (0, 0, 0)) == (-100.0, -1)          # -2000 is below it
    assert sv.value_text(-100.0, -1) == "<= -100 (below the window)"
    assert sv.data_value(narrow, (16, 3, 9)) == (100.0, +1)
    assert sv.value_text(*sv.data_value(narrow, (0, 5, 6)), "HU") == f"{raw_value(0, 5, 6)} HU"
    ct = replace(asymmetric_volume(), dicom_series=SimpleNamespace(modality="CT"))
    assert sv.value_unit(ct) == "HU"
    assert sv.describe_voxel(ct, (16, 3, 9)) == "(16, 3, 9): 8956 HU"
    assert sv.value_unit(asymmetric_volume()) == ""
    windowed = parse_scene({"volume": {"path": "ct/", "window": "bone"}})
    assert sv.value_unit(asymmetric_volume(), windowed) == "HU"
    dose = replace(asymmetric_volume(), dicom_series=SimpleNamespace(modality="RTDOSE"))
    assert sv.value_unit(dose) == "Gy"
    floats = volume_from_array(np.linspace(0, 1, 8, dtype=np.float32).reshape(2, 2, 2) * 3.3,
                               value_range=(0.0, 3.3))
    assert sv.data_value(floats, (1, 1, 1))[0] == pytest.approx(3.3, rel=1e-6)
    assert sv.value_text(1.23456, 0, "Gy") == "1.235 Gy"
    # a DICOM CT's HU arrive as float32 (its rescale applied): whole numbers read as such, through
    # the float32 density; a value between them keeps its fraction
    hu = np.array([-1024.0, -24.0, 0.0, 1234.0, 12.5, 3071.0], np.float32).reshape(1, 2, 3)
    ct_float = volume_from_array(hu, value_range=(-1024.0, 3071.0))
    assert ct_float.raw_dtype == "float32"
    read = [sv.data_value(ct_float, (i, j, 0))[0] for j in range(2) for i in range(3)]
    assert read[:4] == [-1024.0, -24.0, 0.0, 1234.0] and read[5] == 3071.0
    assert [sv.value_text(v, 0) for v in read[1:3]] == ["-24", "0"]
    assert read[4] == pytest.approx(12.5, abs=1e-3) and read[4] != 12.0


# ---- the crop box and the clip plane on a slice ---------------------------------------------------

CROP = {"min": [4, 2, 1], "max": [15, 10, 11], "units": "voxels"}


def test_the_crop_rectangle_lands_where_the_crop_box_is():
    scene = parse_scene({"crop": CROP})
    region = clip_region(scene, (NX, NY, NZ), HALF)
    lo, hi = region.box_min, region.box_max
    # z slice in 200 x 160 px: x 4..15 of 20, y 2..10 of 16 (+y up)
    assert sv.crop_rect(lo, hi, (0, 0, 200, 160), 2, HALF) == pytest.approx(
        (4 / 20 * 200, (1 - 10 / 16) * 160, 15 / 20 * 200, (1 - 2 / 16) * 160))
    # x slice in 120 x 160 px: z 1..11 of 12 runs right to left
    assert sv.crop_rect(lo, hi, (0, 0, 120, 160), 0, HALF) == pytest.approx(
        ((1 - 11 / 12) * 120, (1 - 10 / 16) * 160, (1 - 1 / 12) * 120, (1 - 2 / 16) * 160))
    # y slice in 200 x 120 px, offset: x across, z up
    assert sv.crop_rect(lo, hi, (5, 7, 200, 120), 1, HALF) == pytest.approx(
        (5 + 40, 7 + (1 - 11 / 12) * 120, 5 + 150, 7 + (1 - 1 / 12) * 120))
    # what is kept on the z slice at k = 6: the texels of voxels 4 <= i < 15, 2 <= j < 10
    kept = region.kept(sv.slice_world_points(2, 6, (NX, NY, NZ), HALF))
    rows, cols = np.nonzero(kept)
    assert kept.sum() == 11 * 8
    assert (cols.min(), cols.max()) == (4, 14)
    assert (NY - 1 - rows.max(), NY - 1 - rows.min()) == (2, 9)
    assert not region.kept(sv.slice_world_points(2, 11, (NX, NY, NZ), HALF)).any()   # k = 11 is cut


def test_the_clip_plane_crosses_a_slice_along_its_line():
    lo, hi = -HALF, HALF
    segment = sv.plane_segment((1.0, 0.0, 0.0), 0.1, lo, hi, 2, 0.05)
    np.testing.assert_allclose(sorted(segment[:, 1]), [-0.4, 0.4])
    np.testing.assert_allclose(segment[:, 0], 0.1)
    np.testing.assert_allclose(segment[:, 2], 0.05)
    normal, d = np.array([1.0, 2.0, 0.5]), 0.2
    for axis in range(3):
        seg = sv.plane_segment(normal, d, lo, hi, axis, 0.05)
        assert seg.shape == (2, 3)
        np.testing.assert_allclose(seg @ normal, d, atol=1e-9)
        np.testing.assert_allclose(seg[:, axis], 0.05)
        assert (seg >= lo - 1e-12).all() and (seg <= hi + 1e-12).all()
    assert len(sv.plane_segment((1.0, 0.0, 0.0), 0.7, lo, hi, 2, 0.0)) == 0   # beyond the box
    assert len(sv.plane_segment(normal, d, lo, hi, 2, 0.5)) == 0              # slice off the box


# ---- colours ---------------------------------------------------------------------------------------

def test_slice_colours_are_the_window_or_the_renderers_table():
    d = np.array([[0.0, 0.5], [0.25, 1.0]])
    grey = sv.slice_rgba(d, "window")
    np.testing.assert_array_equal(grey[..., 0], [[0, 128], [64, 255]])
    assert (grey[..., 0] == grey[..., 2]).all() and (grey[..., 3] == 255).all()
    table = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.0]], np.float32)
    tf = sv.slice_rgba(d, "transfer function", table)
    # density 0.5: colour (0.5, 0, 0.5) at opacity 0.5; 1: blue, opaque; 0: clear, black
    np.testing.assert_array_equal(tf[0, 1, :3], [64, 0, 64])
    np.testing.assert_array_equal(tf[1, 1, :3], [0, 0, 255])
    np.testing.assert_array_equal(tf[0, 0, :3], [0, 0, 0])
    shaded = sv.slice_rgba(d, "window", kept=np.array([[True, False], [True, True]]))
    assert shaded[0, 1, 0] == round(0.5 * sv.CUT_AWAY_SHADE * 255) and shaded[1, 1, 0] == 255


def test_recentre_moves_the_orbits_centre_and_keeps_the_view():
    cam = CameraSpec(eye=(0.2, 0.3, 2.0), target=(0.0, 0.1, 0.0))
    moved = orbit.recentre(cam, (0.3, -0.2, 0.1))
    assert moved.target == pytest.approx((0.3, -0.2, 0.1))
    np.testing.assert_allclose(np.subtract(moved.eye, moved.target),
                               np.subtract(cam.eye, cam.target), atol=1e-12)


def test_patient_names_and_edge_letters():
    # "orientation": "patient": +x left, +y superior, +z anterior, as LPS columns
    patient = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    assert [sv.slice_name(a, patient) for a in range(3)] == ["x (sagittal)", "y (axial)",
                                                             "z (coronal)"]
    # axial seen from the feet: the patient's left on the right, anterior up
    assert sv.edge_labels(1, patient) == {"right": "L", "left": "R", "top": "A", "bottom": "P"}
    # sagittal from the left: the face (anterior, +z) on the left
    assert sv.edge_labels(0, patient) == {"right": "P", "left": "A", "top": "S", "bottom": "I"}
    assert sv.slice_name(2) == "z" and sv.edge_labels(0)["right"] == "-z"


def test_the_slice_column_takes_its_width_from_the_3d_view():
    assert sv.column_width("off", (900, 600), 370) == 0.0
    assert sv.column_width("three", (900, 600), 370) == 200.0          # a third of the height
    assert sv.column_width("x", (900, 600), 370) == pytest.approx(265.0)  # half the view
    assert layout.view_rect_window((900, 600), 370, 200) == (370.0, 0.0, 330.0, 600.0)
    # HiDPI: twice the framebuffer pixels; the view ends where the column starts
    assert layout.view_rect_framebuffer((900, 600), (1800, 1200), 370, 200) == (740, 0, 660, 1200)
    assert layout.view_rect_framebuffer((900, 600), (1800, 1200), 370) == (740, 0, 1060, 1200)


# ---- the real viewer -------------------------------------------------------------------------------

WINDOW = (900, 600)
CROP_VOXELS = ["4", "2", "1", "15", "10", "11"]


def image_rect(axis: int) -> tuple[float, float, float, float]:
    """Where the viewer draws the slice across `axis` in a 900 x 600 window at UI scale 1, by
    hand: the column is 200 px wide at x = 700, each slice's box 200 px high (z, y, x from the
    top) less a 3 px gap, less 20 px captions above and below, the image fitted to its world
    extent and centred."""
    box_y = {2: 0, 1: 200, 0: 400}[axis] + 3
    area = (703.0, box_y + 20.0, 194.0, 154.0)
    extent = {2: (1.0, 0.8), 1: (1.0, 0.6), 0: (0.6, 0.8)}[axis]
    scale = min(area[2] / extent[0], area[3] / extent[1])
    w, h = extent[0] * scale, extent[1] * scale
    return (area[0] + (area[2] - w) / 2, area[1] + (area[3] - h) / 2, w, h)


def texel_centre(rect, column: int, row: int, columns: int, rows: int) -> list[float]:
    x, y, w, h = rect
    return [x + (column + 0.5) / columns * w, y + (row + 0.5) / rows * h]


def grey(raw: float, kept: bool = True) -> int:
    d = (raw - LOW) / (HIGH - LOW)
    return round(d * (1.0 if kept else sv.CUT_AWAY_SHADE) * 255)


@pytest.fixture(scope="module")
def session(display, tmp_path_factory):
    out = tmp_path_factory.mktemp("slices")
    np.save(out / "asym.npy", asymmetric_raw())
    z_rect, x_rect = image_rect(2), image_rect(0)
    steps = [
        {"frames": 2}, {"dump": "start.json"}, {"screenshot": "start.png"},
        # hover voxel (16, 3, 6) of the z slice: column 16, row 15 - 3
        {"move": texel_centre(z_rect, 16, NY - 1 - 3, NX, NY)}, {"dump": "hover.json"},
        # click voxel (10, 2, 9) of the x slice: column 11 - 9, row 15 - 2
        {"click": texel_centre(x_rect, NZ - 1 - 9, NY - 1 - 2, NZ, NY)}, {"dump": "clicked.json"},
        {"move": texel_centre(z_rect, 16, NY - 1 - 3, NX, NY)}, {"dump": "hover_block.json"},
        {"screenshot": "clicked.png"},
        {"scroll": texel_centre(z_rect, 3, 3, NX, NY), "steps": -1}, {"dump": "scrolled.json"},
        {"key": "v"}, {"frames": 1}, {"dump": "one.json"},
        {"close": True},
    ]
    script = write_script(out / "script.json", steps)
    view(["asym.npy", "--value-range=-2000,10000", "--slices", "--crop-voxels", *CROP_VOXELS,
          "--method", "raymarch", "--render-scale", "0.25", "--spp", "1", "--window",
          f"{WINDOW[0]}x{WINDOW[1]}", "--script", str(script)], out, display)
    return out


def test_the_slices_are_drawn_beside_the_3d_view(session):
    d = dump(session / "start.json")
    assert d["errors"] == []
    assert d["view_rect_window"] == [370.0, 0.0, 330.0, 600.0]      # the column took 200 px
    s = d["slices"]
    assert s["view"] == "three" and s["indices"] == [10, 8, 6]
    for axis in "zyx":
        assert s["rects"][axis] == pytest.approx(image_rect("xyz".index(axis)))
    assert s["hovered"] is None


def test_the_slice_shows_the_data_the_right_way_round_with_the_crop(session):
    """The z slice (k = 6) read back from the window: each texel the window's grey of its voxel,
    darkened where the crop cuts it away; the crop's edges drawn in the crop colour where the crop
    box is (x 4..15 of 20, y 2..10 of 16), and not inside it."""
    image = png(session / "start.png")
    rect = image_rect(2)

    def at(column, row):
        x, y = texel_centre(rect, column, row, NX, NY)
        return image[int(y), int(x)]

    for i, j, kept in ((6, 5, True), (12, 7, True), (1, 5, False), (17, 12, False),
                       (6, 14, False), (3, 0, False)):
        expected = grey(raw_value(i, j, 6), kept)
        np.testing.assert_allclose(at(i, NY - 1 - j), [expected] * 3, atol=2,
                                   err_msg=f"voxel ({i}, {j}, 6)")
    x0, y0, w, h = rect
    left, right = x0 + 4 / 20 * w, x0 + 15 / 20 * w
    top, bottom = y0 + (1 - 10 / 16) * h, y0 + (1 - 2 / 16) * h
    rows = np.linspace(top + 8, bottom - 8, 6).astype(int)
    cols = np.linspace(left + 8, right - 8, 6).astype(int)

    def yellow(p) -> bool:
        return bool(p[0] - p[2] > 120 and p[1] - p[2] > 80)

    def near(edge: float) -> range:   # the pixels within one of an edge (a line 2 px wide)
        return range(int(edge) - 1, int(edge) + 2)

    for edge in (left, right):
        assert all(any(yellow(image[r, x]) for x in near(edge)) for r in rows), \
            f"no crop edge at x = {edge}"
        assert not any(yellow(image[r, int(edge) + (6 if edge == left else -6)]) for r in rows)
    for edge in (top, bottom):
        assert all(any(yellow(image[y, c]) for y in near(edge)) for c in cols), \
            f"no crop edge at y = {edge}"
        assert not any(yellow(image[int(edge) + (6 if edge == top else -6), c]) for c in cols)
    # the crop does not reach the slice's own edges
    assert not any(yellow(image[r, int(x0 + 2)]) for r in rows)


def test_the_value_under_the_mouse_is_in_data_units(session):
    hovered = dump(session / "hover.json")["slices"]["hovered"]
    assert hovered["axis"] == "z" and hovered["voxel"] == [16, 3, 6]
    assert hovered["text"] == f"(16, 3, 6): {raw_value(16, 3, 6)}"
    block = dump(session / "hover_block.json")["slices"]["hovered"]
    assert block["voxel"] == [16, 3, 9] and block["text"] == "(16, 3, 9): 8956"


def test_a_click_in_a_slice_moves_the_slices_and_the_orbits_centre(session):
    start, clicked = dump(session / "start.json"), dump(session / "clicked.json")
    assert clicked["slices"]["indices"] == [10, 2, 9]
    voxel = [centre(10, NX, 0.5), centre(2, NY, 0.4), centre(9, NZ, 0.3)]
    cam0, cam1 = start["scene"]["camera"], clicked["scene"]["camera"]
    np.testing.assert_allclose(cam1["target"], voxel, atol=1e-6)
    np.testing.assert_allclose(np.subtract(cam1["eye"], cam1["target"]),
                               np.subtract(cam0["eye"], cam0["target"]), atol=1e-6)


def test_the_block_shows_where_the_3d_view_has_it(session):
    """After the click the z slice is k = 9, through the block (high x, low y): bright at the
    bottom right, kept inside the crop (x < 15), darkened beyond it."""
    image = png(session / "clicked.png")
    rect = image_rect(2)

    def at(i, j):
        x, y = texel_centre(rect, i, NY - 1 - j, NX, NY)
        return int(image[int(y), int(x), 0])

    assert at(13, 3) == pytest.approx(grey(raw_value(13, 3, 9)), abs=2)          # kept block
    assert at(16, 3) == pytest.approx(grey(raw_value(16, 3, 9), False), abs=2)   # cut block
    assert at(13, 3) > 200 and at(6, 3) < 100                    # the block, not its mirror


def test_the_wheel_steps_a_slice_and_v_shows_one(session):
    assert dump(session / "scrolled.json")["slices"]["indices"] == [10, 2, 8]
    one = dump(session / "one.json")
    assert one["slices"]["view"] == "x" and list(one["slices"]["rects"]) == ["x"]
    assert one["view_rect_window"][2] == pytest.approx(900 - 370 - 265.0)
