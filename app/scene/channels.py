"""Several channels (SPEC.md, Channels): which channels a scene shows, their transfer tables, and
what the volume texture depends on.

A scene without a channels key shows a one-channel volume as always, or every channel of a file
of 2 to MAX_CHANNELS with the default colour of its place (scene_types.channel_transfer_function).
The medium they make is combined in one place, glsl/lib/medium.glsl (NumPy twin
app/twins/medium.py): extinctions add, the albedo is their extinction-weighted mix.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from radiance_probes.scene.flags import with_flag
from radiance_probes.scene.types import (MAX_CHANNELS, ChannelSpec, Scene, SceneError,
                                         TransferFunctionSpec, VolumeError,
                                         channel_transfer_function)
from radiance_probes.scene.transfer import transfer_table


def default_channels(count: int, where: str) -> tuple[ChannelSpec, ...]:
    """A file's channels where the scene names none: each shown, in the colour of its place."""
    if count > MAX_CHANNELS:
        raise VolumeError(f"{where}: the volume has {count} channels; at most {MAX_CHANNELS} are "
                          "shown at once: choose them with the scene's channels list, e.g. "
                          "\"channels\": [{\"index\": 0}, {\"index\": 2}] (--channel 0,2)")
    return tuple(ChannelSpec(transfer_function=channel_transfer_function(i), index=i)
                 for i in range(count))


def check_channel_count(channels: tuple[ChannelSpec, ...], count: int, where: str) -> None:
    """Raises VolumeError where a channel names a channel the volume lacks."""
    for i, ch in enumerate(channels):
        index = i if ch.index is None else ch.index
        if index >= count:
            has = "one channel" if count == 1 else f"{count} channels (0 to {count - 1})"
            raise VolumeError(f"{where}: channels[{i}] shows the file's channel {index}, but the "
                              f"volume has {has}; --channel I,J,... picks them")


def scene_channels(scene: Scene) -> tuple[ChannelSpec, ...] | None:
    """The channels the scene names (None: it names none)."""
    return scene.channels or None


def effective_channels(scene: Scene, count: int) -> tuple[ChannelSpec, ...] | None:
    """The channels shown of a loaded volume of `count` channels (a Volume holds the channels
    the scene shows, in the scene's order: load_scene_volume), or None for one channel shown
    with the scene's transfer_function."""
    if scene.channels:
        if len(scene.channels) != count:
            raise VolumeError(f"channels: the scene shows {len(scene.channels)} channels but the "
                              f"volume holds {count}")
        return scene.channels
    if count == 1:
        return None
    if scene.transfer_function != TransferFunctionSpec():
        raise SceneError(f"transfer_function: the volume has {count} channels; give each its own "
                         f"(channels[i].transfer_function: --channel "
                         f"{','.join(map(str, range(count)))} makes the list, then --set "
                         "channels[0].transfer_function.colormap=NAME) instead of one for the "
                         "scene")
    return default_channels(count, "volume")


def volume_inputs(scene: Scene) -> tuple:
    """What the volume's texture depends on: the volume key, the channels' file indices and
    windows (not their transfer functions or switches, which leave the texture as it is) and the
    time step."""
    return (scene.volume, scene.base_dir,
            tuple((c.index, c.value_range, c.window) for c in scene.channels), scene.time)


@dataclass(frozen=True, eq=False)
class ChannelTables:
    """The transfer tables of several channels, in the volume texture's order, and which are
    switched on (the twins in app/twins take one in place of a one-channel table)."""
    tables: tuple[np.ndarray, ...]
    on: tuple[bool, ...]

    @classmethod
    def of(cls, channels: tuple[ChannelSpec, ...]) -> "ChannelTables":
        return cls(tuple(transfer_table(c.transfer_function) for c in channels),
                   tuple(bool(c.enabled) for c in channels))

    @property
    def count(self) -> int:
        return len(self.tables)

    @property
    def weights(self) -> np.ndarray:
        """1 for a channel switched on, 0 off (the shaders' channel_on)."""
        return np.array([1.0 if o else 0.0 for o in self.on], np.float32)

    @property
    def stride(self) -> int:
        """Rows of the padded table texture (the longest table)."""
        return max(len(t) for t in self.tables)

    def padded(self) -> np.ndarray:
        """float32 (count, stride, 4): each table padded with its last row."""
        out = np.empty((self.count, self.stride, 4), np.float32)
        for c, t in enumerate(self.tables):
            out[c, :len(t)] = t
            out[c, len(t):] = t[-1]
        return out


def channel_uniforms(tables: ChannelTables) -> dict:
    """The uniforms of lib/medium.glsl's several channels (MEDIUM_CHANNELS > 1)."""
    sizes = [len(t) for t in tables.tables] + [2] * (4 - tables.count)
    weights = list(map(float, tables.weights)) + [0.0] * (4 - tables.count)
    return {"channel_transfer_size": tuple(sizes), "transfer_stride": tables.stride,
            "channel_on": tuple(weights), "transfer_size": len(tables.tables[0])}
