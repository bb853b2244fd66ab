"""Zarr and OME-Zarr stores too large to read whole: the volume read brick by brick (a BrickStore
behind LazyData) and a time series' value range read once."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from radiance_probes.io import volume_formats as formats
from radiance_probes.scene.flags import flag_for
from radiance_probes.scene.types import VolumeError
from radiance_probes.io.volume_axes import resolve_axes
from radiance_probes.io.volume import Volume, normalise
from radiance_probes.io.volume_files import time_note


# A Zarr volume larger than this (as float32) or longer than LAZY_SIDE along an axis is read
# brick by brick (app/io/volume.py load_volume) instead of whole.
LAZY_BYTES = 1 << 30


LAZY_SIDE = 2048


def lazy_zarr_volume(p, spec, time: int, channels, brick: int):
    """A Volume of a Zarr store read brick by brick (Volume.data a LazyData, Volume.bricks its
    BrickStore, Volume.levels the store's coarser levels, which read the same channels with the
    same value ranges): the time step `time`, the channels shown (as the whole loader chooses
    them: volume_from_canonical; several read as [z, y, x, c]); each channel normalised as the
    whole loader does (its value range, else the type's for 8-bit data, else its least and
    largest value, from the range pass)."""
    from radiance_probes.io.bricks import BrickStore, LazyData
    from radiance_probes.io.brick_sources import ZarrSource
    from radiance_probes.scene.channels import check_channel_count, default_channels
    from radiance_probes.scene.types import MAX_CHANNELS
    from radiance_probes.io.volume_formats import open_zarr
    where = str(p)
    array, file_spacing, axes, levels = open_zarr(p, spec.spacing is None)
    axes = resolve_axes(axes, tuple(array.shape), spec.axes, where)
    if any(a not in "tczyx" for a in axes) or not all(a in axes for a in "zyx"):
        raise VolumeError(f"{where}: axes {axes!r}; a bricked Zarr store needs z, y and x")
    size = dict(zip(axes, array.shape))
    steps = size.get("t", 1)
    if not 0 <= time < steps:
        raise VolumeError(f"{where}: time step {time} asked for, but the volume has "
                          + (f"{steps} time steps (0 to {steps - 1})" if steps > 1 else
                             "no time axis (one step)") + "; see the scene's time (--time STEP)")
    count = size.get("c", 1)
    if channels is None and count > 1:
        channels = default_channels(count, where)       # more than MAX_CHANNELS refused
    if channels is not None:
        if len(channels) > MAX_CHANNELS:
            raise VolumeError(f"{where}: {len(channels)} channels, at most {MAX_CHANNELS} are "
                              "shown at once (choose them with channels[i].index, "
                              f"{flag_for('channels')})")
        check_channel_count(channels, count, where)     # a channel the store lacks refused
        shown = [i if ch.index is None else ch.index for i, ch in enumerate(channels)]
        labels = [f"{where} (channel {index}{f' {ch.name}' if ch.name else ''})"
                  for index, ch in zip(shown, channels)]
        domains = [ch.domain(spec) for ch in channels]
    else:
        shown, labels, domains = [0], [where], [spec.domain]
    many = len(shown) > 1
    spacing = spec.spacing or file_spacing or (1.0, 1.0, 1.0)

    def source_of(a, ranges, step=time):
        return ZarrSource(a, axes, step, shown[0], ranges[0], where, spec.replace_nonfinite,
                          normalise, channels=shown if many else None, value_ranges=ranges)

    source = source_of(array, [None] * len(shown))
    store = BrickStore(source, brick, p.name)
    # The range pass (every brick read once) is needed here only where a channel's values map
    # by its own least and largest; else it waits for the placement, which may never need it
    # (a cap that a coarser level shows that level 0 exceeds: app/rendering/levels/volume_placement.py),
    # and the raw extremes are NaN until it is read (Volume.raw_extents).
    by_extremes = (any(d is None for d in domains)
                   and array.dtype not in (np.uint8, np.int8))
    if by_extremes:
        lows, highs = store.raw_extremes()
    else:
        lows = highs = np.full(len(shown), np.nan)
    series_lows, series_highs = lows, highs
    if steps > 1 and by_extremes:
        # SPEC.md, Time series: every step normalised alike, by the whole series' range where
        # the scene gives none: each other step's range pass (once per store)
        series_lows, series_highs = _series_extremes(
            p, steps, time, lows, highs, lambda step: source_of(array, [None] * len(shown), step),
            brick, (axes, tuple(shown), spec.replace_nonfinite))
    ranges, raws = [], []
    for c, (domain, label) in enumerate(zip(domains, labels)):
        # the channel's least and largest raw values (of the series, where it is one),
        # normalised as the whole loader normalises the channel: its domain, else the type's
        # (8-bit), else these (refused where equal); raw_min/max are the step's own
        extremes = (np.array([series_lows[c], series_highs[c]], array.dtype) if by_extremes
                    else np.zeros(2, array.dtype))     # (a domain: the values are not looked at)
        ranges.append(normalise(extremes, domain, label)[1])
        raws.append((float(lows[c]), float(highs[c])))
    source.value_range, source.value_ranges = ranges[0], ranges
    coarser = [source_of(a, ranges) for a in levels[1:]]
    notes = time_note(p.name, steps, time)
    if spec.orientation == "patient":
        notes += (f"{p.name} says nothing of the patient's orientation: shown as stored "
                  "(orientation \"data\")",)
    volume = Volume(LazyData(store), tuple(float(v) for v in spacing), p.name, ranges[0],
                    array.dtype.name, *raws[0], notes=notes, bricks=store,
                    levels=tuple(coarser),
                    **({"channel_ranges": tuple(ranges), "channel_raw": tuple(raws)}
                       if many else {}))
    return dataclasses.replace(volume, time=time, time_steps=steps) if steps > 1 else volume


# Each bricked time series' raw extremes over all its steps, per channel shown: {key: (lows, highs)}.
_SERIES_EXTREMES: dict = {}


def _series_extremes(p, steps: int, time: int, lows, highs, source_at, brick: int, reading):
    """Per channel shown, the least and largest raw values over every step of a bricked Zarr
    time series (`lows`, `highs`: step `time`'s, already read; source_at(step): a step's
    ZarrSource; `reading`: what else the values depend on): the other steps' range passes, once
    per store (kept while its files are unchanged)."""
    from radiance_probes.io.bricks import BrickStore
    try:
        stamp = p.stat().st_mtime_ns
    except OSError:
        stamp = None
    key = (str(p.resolve()), stamp, reading)
    if key not in _SERIES_EXTREMES or stamp is None:
        lo, hi = np.array(lows), np.array(highs)
        for step in range(steps):
            if step == time:
                continue
            step_lo, step_hi = BrickStore(source_at(step), brick, p.name).raw_extremes()
            lo, hi = np.minimum(lo, step_lo), np.maximum(hi, step_hi)
        _SERIES_EXTREMES.clear()          # one series at a time
        _SERIES_EXTREMES[key] = (lo, hi)
    return _SERIES_EXTREMES[key]


def _large_zarr(p: Path) -> bool:
    """A Zarr store too large to read whole (app/io/bricks.py LAZY_BYTES, LAZY_SIDE)."""
    array = formats.open_zarr(p)[0]
    spatial = sorted(array.shape)[-3:]
    return 4 * int(np.prod(array.shape, dtype=np.int64)) > LAZY_BYTES or max(spatial) > LAZY_SIDE
