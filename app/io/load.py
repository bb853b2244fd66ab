"""The one entry point that turns a scene's volume into a Volume: `load_volume` (a built-in, a
file, a folder, a series, a large store read brick by brick), `load_scene_volume`, whether a
scene's store is read lazily, and the viewer's small preview of a large store."""
from __future__ import annotations

import dataclasses

import numpy as np

from radiance_probes.io import volume_formats as formats
from radiance_probes.io.orientation import patient_axes, to_patient
from radiance_probes.scene.flags import with_flag
from radiance_probes.scene.types import Scene, VolumeError, VolumeSpec
from radiance_probes.io.volume_axes import resolve_axes
from radiance_probes.io.builtin_volumes import BUILTIN_VOLUMES
from radiance_probes.io.lazy_zarr import _large_zarr, lazy_zarr_volume
from radiance_probes.io.volume import Volume, normalise, volume_from_canonical
from radiance_probes.io.volume_files import _read_series, _resolve, _series_domains, time_note


def load_volume(spec: VolumeSpec, base_dir: str | None = None,
                channels: tuple | None = None, time: int = 0,
                brick: int | None = None) -> Volume:
    """Load the volume a scene names: a built-in or a file; errors name the file and the problem.
    `channels`: the channels to show (app/scene/channels.py effective_channels; None: a file of one
    channel, or its channels with their defaults). `time`: the step of a time series (SPEC.md,
    Time series: every step normalised alike, by the whole series' range where the scene gives
    none). A Zarr store larger than app/io/lazy_zarr.py LAZY_BYTES or LAZY_SIDE, or any with `brick`
    given, is read brick by brick (bricks of `brick` voxels, default 64) instead of whole."""
    spacing = spec.spacing if spec.spacing is not None else (1.0, 1.0, 1.0)
    if spec.path is None:
        name = spec.builtin or "cloud"
        if name not in BUILTIN_VOLUMES:
            raise VolumeError(f"unknown built-in volume '{name}' (known: {', '.join(BUILTIN_VOLUMES)})")
        if time != 0:
            raise VolumeError(f"built-in '{name}': time step {time} asked for, but the volume has "
                              "no time axis (one step); see the scene's time (--time STEP)")
        if spec.rescale is not None:
            raise VolumeError(f"built-in '{name}': {with_flag('volume.rescale')} applies to a "
                              "file's stored values")
        data = BUILTIN_VOLUMES[name](tuple(spec.size))
        domain = spec.domain
        if channels is not None:
            from radiance_probes.scene.channels import check_channel_count
            check_channel_count(channels, 1, f"built-in '{name}'")
            domain = channels[0].domain(spec)
        vr = domain or (0.0, 1.0)
        norm, vr = normalise(data, vr, f"built-in '{name}'")
        return Volume(norm, tuple(float(v) for v in spacing), f"builtin:{name}", vr, "float32",
                      float(data.min()), float(data.max()))
    p = _resolve(spec.path, base_dir)
    if formats.is_zarr(p) and (brick is not None or _large_zarr(p)) and spec.rescale is not None:
        raise VolumeError(f"{p}: {with_flag('volume.rescale')} is not applied to a Zarr store read "
                          "brick by brick; give its range in stored values "
                          f"({with_flag('volume.value_range')})")
    if formats.is_zarr(p) and (brick is not None or _large_zarr(p)):
        from radiance_probes.io.brick_layout import DEFAULT_BRICK_SIZE
        return lazy_zarr_volume(p, spec, time, channels, brick or DEFAULT_BRICK_SIZE)
    found = _read_series(spec, base_dir)
    raw, name, direction, notes = found.raw, found.name, found.direction, found.notes
    where = str(_resolve(spec.path, base_dir))
    if spec.rescale is not None:
        if found.series is not None:
            raise VolumeError(f"{where}: {with_flag('volume.rescale')} is for data exported without "
                              "its units; a DICOM series carries its own RescaleSlope and "
                              "RescaleIntercept, which are applied")
        slope, intercept = spec.rescale
        raw = raw.astype(np.float32) * np.float32(slope) + np.float32(intercept)
    if found.spacing is not None:
        spacing = found.spacing  # the header's spacing unless the scene gives one (even 1, 1, 1)
    if any(not (s > 0 and np.isfinite(s)) for s in spacing):
        raise VolumeError(f"{where}: spacing must be positive, got {spacing}")
    steps = raw.shape[0]
    if not 0 <= time < steps:
        raise VolumeError(f"{where}: time step {time} asked for, but the volume has "
                          + (f"{steps} time steps (0 to {steps - 1})" if steps > 1 else
                             "no time axis (one step)") + "; see the scene's time (--time STEP)")
    fallback = _series_domains(raw, spec) if steps > 1 else None
    notes += time_note(name, steps, time)
    step = raw[time]
    oblique = 0.0
    orientation = "data"
    if spec.orientation == "patient":
        if direction is None:
            notes += (f"{name} says nothing of the patient's orientation: shown as stored "
                      "(orientation \"data\")",)
        else:   # every channel placed alike (the same permutation and flips)
            placed = [to_patient(step[c], spacing, direction) for c in range(step.shape[0])]
            step = np.stack([p.data for p in placed])
            direction, orientation = placed[0].direction, "patient"
            # a scene's spacing is given along the file's axes, like the header's
            spacing = placed[0].spacing
            oblique = placed[0].oblique_degrees
            if oblique:
                notes += (f"{name} was scanned obliquely: its axes lie {oblique:.1f} degrees "
                          "from the patient's; shown on the nearest patient axes (permuted and "
                          f"flipped, not resampled: {patient_axes(direction)})",)
    volume = volume_from_canonical(step, tuple(float(s) for s in spacing), name, spec,
                                   channels, where, fallback)
    return dataclasses.replace(
        volume, notes=notes, direction=direction, orientation=orientation,
        oblique_degrees=oblique, dicom_listing=found.listing, dicom_series=found.series,
        **({"time": time, "time_steps": steps} if steps > 1 else {}))


def load_scene_volume(scene: Scene, brick: int | None = None) -> Volume:
    from radiance_probes.scene.channels import scene_channels
    from radiance_probes.scene.clinical_presets import check_hounsfield
    volume = load_volume(scene.volume, scene.base_dir, scene_channels(scene), scene.time, brick)
    if not scene.channels:
        # a CT window or clinical preset on data not in Hounsfield units: refused, naming both
        check_hounsfield(scene.volume, scene.transfer_function.preset, volume)
    return volume


# A preview of a Zarr store read brick by brick (app/rendering/levels/progressive_open.py): its finest level
# of at most this many voxels, read whole (256^3 of a 2048^3 store: a fraction of a second).
PREVIEW_VOXELS = 1 << 25


def reads_lazily(scene: Scene, brick: int | None = None) -> bool:
    """Whether the scene's volume is a Zarr store that load_volume reads brick by brick."""
    spec = scene.volume
    if spec.path is None:
        return False
    p = _resolve(spec.path, scene.base_dir)
    return formats.is_zarr(p) and (brick is not None or _large_zarr(p))


def zarr_preview(scene: Scene, max_voxels: int = PREVIEW_VOXELS,
                 memory_bytes: int | None = None) -> Volume | None:
    """A quick stand-in for a Zarr store read brick by brick, in the same world box: the finest
    of its own coarser levels (OME-Zarr multiscales) of at most `max_voxels` voxels (and within
    `memory_bytes` as float32, the volume's GPU memory cap), read whole,
    normalised by the scene's value range, else the type's for 8-bit data, else the level's own
    least and largest (which its note calls provisional: the store's are known only after its
    range pass); where the store has no such level, an empty box. None for a store of several
    channels, or a time step it lacks (the full open says what is wrong)."""
    from radiance_probes.io.brick_sources import ZarrSource
    from radiance_probes.scene.channels import scene_channels
    from radiance_probes.io.volume_formats import open_zarr
    spec = scene.volume
    p = _resolve(spec.path, scene.base_dir)
    where = str(p)
    array, file_spacing, axes, levels = open_zarr(p, spec.spacing is None)
    axes = resolve_axes(axes, tuple(array.shape), spec.axes, where)
    size = dict(zip(axes, array.shape))
    channels = scene_channels(scene)
    if size.get("c", 1) > 1 or (channels is not None and len(channels) > 1):
        return None
    if not 0 <= scene.time < size.get("t", 1):
        return None
    spacing = spec.spacing or file_spacing or (1.0, 1.0, 1.0)
    dims0 = [size[a] for a in "xyz"]
    if memory_bytes is not None:
        max_voxels = min(max_voxels, memory_bytes // 4)

    def in_box(data, note, value_range=(0.0, 1.0), lo=0.0, hi=0.0) -> Volume:
        dims = data.shape[:3][::-1]
        scaled = tuple(float(s) * n0 / n for s, n0, n in zip(spacing, dims0, dims))
        return Volume(data, scaled, p.name, value_range, array.dtype.name, lo, hi, notes=(note,))

    small = [a for a in levels[1:]
             if int(np.prod([dict(zip(axes, a.shape))[k] for k in "zyx"])) <= max_voxels]
    domain = spec.domain if channels is None else channels[0].domain(spec)
    raw = None
    if small:
        level = small[0]
        shape = [dict(zip(axes, level.shape))[k] for k in "zyx"]
        source = ZarrSource(level, axes, scene.time, 0, domain, where, spec.replace_nonfinite,
                            normalise)
        raw = source.read(0, shape[0], 0, shape[1], 0, shape[2])
        if domain is None and raw.dtype not in (np.uint8, np.int8) and not raw.max() > raw.min():
            raw = None
    if raw is None:
        return in_box(np.zeros((2, 2, 2), np.float32),
                      f"{p.name} is loading; it has no level small enough to preview")
    provisional = ""
    if domain is None and raw.dtype not in (np.uint8, np.int8):
        provisional = (" (densities provisional: this level's own least and largest values, until "
                       "the store's range pass)")
    data, value_range = normalise(raw, domain, where)
    nz = raw.shape[0]
    note = (f"preview: a {size['z'] / nz:.0f}x coarser level ({raw.shape[2]} x {raw.shape[1]} x "
            f"{nz}) while {p.name} loads{provisional}")
    return in_box(data, note, value_range, float(raw.min()), float(raw.max()))


def volume_from_array(array, axes: str = "zyx", spacing=(1.0, 1.0, 1.0),
                      value_range: tuple[float, float] | None = None,
                      channels: tuple | None = None, time: int = 0,
                      name: str = "array") -> Volume:
    """A Volume from a NumPy array in memory (the Python API's way in): `axes` names its axes as
    volume.axes does ("zyx", "czyx", "tzyx", "tczyx", ...); `channels` and `time` as the scene's
    (app/scene/channels.py, SPEC.md); normalised as a file's would be. Errors are VolumeErrors naming
    the problem."""
    from radiance_probes.io.volume_axes import resolve_axes, to_canonical
    data = np.asarray(array)
    if not isinstance(axes, str):
        raise VolumeError(f"{name}: axes must be a string such as \"czyx\", got {axes!r}")
    raw = to_canonical(data, resolve_axes(None, tuple(data.shape), axes.lower(), name), name)
    if min(raw.shape) < 1:
        raise VolumeError(f"{name}: volume has zero size, shape {list(data.shape)}")
    spacing = tuple(float(v) for v in spacing)
    if len(spacing) != 3 or any(not (v > 0 and np.isfinite(v)) for v in spacing):
        raise VolumeError(f"{name}: spacing must be three positive numbers, got {list(spacing)}")
    steps = raw.shape[0]
    if not 0 <= time < steps:
        raise VolumeError(f"{name}: time step {time} asked for, but the array has "
                          + (f"{steps} time steps" if steps > 1 else "no time axis"))
    spec = VolumeSpec(path=name, builtin=None, value_range=value_range)
    volume = volume_from_canonical(raw[time], spacing, name, spec, channels, name,
                                   _series_domains(raw, spec) if steps > 1 else None)
    return dataclasses.replace(volume, time=time, time_steps=steps) if steps > 1 else volume
