"""GPU textures for the volume and the transfer function, with errors that name the problem."""
from __future__ import annotations

import moderngl
import numpy as np

from radiance_probes.io.volume import Volume, VolumeError


def _check_gl(ctx: moderngl.Context, what: str) -> None:
    err = ctx.error
    if err != "GL_NO_ERROR":
        if err == "GL_OUT_OF_MEMORY":
            raise VolumeError(f"{what}: not enough GPU memory")
        raise VolumeError(f"{what}: OpenGL error {err}")


BRICKING_HINT = "a volume that does not fit is read in bricks instead (docs/bricking.md)"


def check_volume_fits(name: str, dims: tuple[int, int, int], bytes_per_voxel: int,
                      max_side: int, available: int | None, where: str) -> None:
    """Raises VolumeError unless a dims volume fits one 3D texture: every side within
    GL_MAX_3D_TEXTURE_SIZE and its bytes within the memory the device has left (``available``,
    None where the device cannot tell)."""
    if max(dims) > max_side:
        raise VolumeError(f"{name}: dimensions {dims} exceed this GPU's GL_MAX_3D_TEXTURE_SIZE of "
                          f"{max_side} voxels per side; {BRICKING_HINT}")
    need = int(np.prod(np.asarray(dims, np.int64))) * bytes_per_voxel
    if available is not None and need > available:
        raise VolumeError(f"{name}: the {dims[0]} x {dims[1]} x {dims[2]} volume needs "
                          f"{need / 2**30:.2f} GiB as a 3D texture, more than the "
                          f"{available / 2**30:.2f} GiB of {where}; {BRICKING_HINT}")


def device_available(ctx: moderngl.Context) -> tuple[int | None, str]:
    """The bytes a volume may take on this device (None where it cannot tell), and what they are."""
    from radiance_probes.gl.context import is_software as software_renderer
    from radiance_probes.gl.memory import gpu_available_bytes, host_available_bytes
    if software_renderer(ctx):
        # the texture lives in host memory, beside the upload's payload and its bytes copy
        available = host_available_bytes()
        return (None if available is None else available // 3,
                "host memory available (MemAvailable)")
    return gpu_available_bytes(ctx), "GPU memory available (GL_NVX_gpu_memory_info)"


def texture_payload(volume: Volume) -> np.ndarray:
    """The texels volume_texture uploads (16-bit normalised for exact 8-bit data, else float32):
    NumPy, no GL, so a volume opening in the viewer has them made on its loading thread (0.5 s of
    a 1.4 s upload for the foot); kept in volume.derived until uploaded."""
    key = ("texture payload", id(volume.data))
    if key not in volume.derived:
        volume.derived[key] = (
            (np.round(volume.data * 255.0).astype(np.uint16) * 257).astype(np.uint16)
            if volume.exact_uint8 else np.ascontiguousarray(volume.data, np.float32))
    return volume.derived[key]


def volume_texture(ctx: moderngl.Context, volume: Volume) -> moderngl.Texture3D:
    """A 3D texture of one component a channel (R, RG, RGB or RGBA), linear, clamped to edge:
    16-bit normalised for exact 8-bit data (k * 257 / 65535
    is exactly k / 255, and llvmpipe filters 8-bit textures with 8-bit intermediate rounding), else
    R32F, so 16-bit and float data keep their precision (float32 holds every 16-bit step exactly).
    Refused before any allocation when it exceeds GL_MAX_3D_TEXTURE_SIZE or the memory left."""
    channels = volume.channel_count
    texel = (2 if volume.exact_uint8 else 4) * channels
    available, where = device_available(ctx)
    check_volume_fits(volume.name, volume.dims, texel, int(ctx.info["GL_MAX_3D_TEXTURE_SIZE"]),
                      available, where)
    payload = texture_payload(volume)
    volume.derived.pop(("texture payload", id(volume.data)), None)   # (uploaded: not kept)
    dtype = "nu2" if volume.exact_uint8 else "f4"
    ctx.error  # clear any earlier error flag
    try:
        tex = ctx.texture3d(volume.dims, channels, payload.tobytes(), dtype=dtype, alignment=1)
    except moderngl.Error as exc:
        raise VolumeError(f"{volume.name}: cannot create a {volume.dims} 3D texture ({exc})") from None
    _check_gl(ctx, f"{volume.name} ({payload.nbytes / 2**20:.0f} MiB 3D texture)")
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    tex.repeat_x = tex.repeat_y = tex.repeat_z = False
    return tex


# Storage-buffer binding of the transfer table (lib/medium.glsl TransferTable; bindings 0 to 7 are
# the passes' own buffers).
TRANSFER_TABLE_BINDING = 8


def transfer_buffer_bindable(ctx: moderngl.Context) -> bool:
    """Whether the device has storage-buffer binding TRANSFER_TABLE_BINDING (GL 4.3 promises only
    0 to 7; NVIDIA's and Mesa's drivers have dozens)."""
    return int(ctx.info.get("GL_MAX_SHADER_STORAGE_BUFFER_BINDINGS", 0)) > TRANSFER_TABLE_BINDING


class TransferTable:
    """The RGBA table on the GPU twice, with the same float32 values: an N x 1 RGBA32F texture
    (read with texelFetch and interpolated exactly) and a storage buffer, which compute passes
    read on a GPU (lib/medium.glsl TRANSFER_FROM_BUFFER; app/gl/shaders.py transfer_from_buffer).
    Several channels (an app.channels.ChannelTables): one row of the texture a channel, each
    padded to the longest table, and the buffer the rows one after another."""

    def __init__(self, ctx: moderngl.Context, table):
        if hasattr(table, "padded"):
            padded = table.padded()
            data = np.ascontiguousarray(padded.reshape(-1, 4), np.float32)
            size = (padded.shape[1], padded.shape[0])
        else:
            data = np.ascontiguousarray(table, np.float32)
            size = (len(data), 1)
        self.texture = ctx.texture(size, 4, data.tobytes(), dtype="f4")
        self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.texture.repeat_x = self.texture.repeat_y = False
        self.buffer = ctx.buffer(data.tobytes())
        self.bindable = transfer_buffer_bindable(ctx)

    def use(self, unit: int) -> None:
        """Binds the texture to `unit` and the buffer to TRANSFER_TABLE_BINDING (where it exists)."""
        self.texture.use(unit)
        if self.bindable:
            self.buffer.bind_to_storage_buffer(TRANSFER_TABLE_BINDING)

    def release(self) -> None:
        self.texture.release()
        self.buffer.release()

