"""GPU textures for the volume and the transfer function, with errors that name the problem."""
from __future__ import annotations

import moderngl
import numpy as np

from ..volume import Volume, VolumeError


def _check_gl(ctx: moderngl.Context, what: str) -> None:
    err = ctx.error
    if err != "GL_NO_ERROR":
        if err == "GL_OUT_OF_MEMORY":
            raise VolumeError(f"{what}: not enough GPU memory")
        raise VolumeError(f"{what}: OpenGL error {err}")


def volume_texture(ctx: moderngl.Context, volume: Volume) -> moderngl.Texture3D:
    """A one-channel 3D texture, linear, clamped to edge: R16 for exact 8-bit data (k * 257 / 65535
    is exactly k / 255, and llvmpipe filters 8-bit textures with 8-bit intermediate rounding), else
    R32F."""
    limit = ctx.info["GL_MAX_3D_TEXTURE_SIZE"]
    if max(volume.dims) > limit:
        raise VolumeError(f"{volume.name}: dimensions {volume.dims} exceed this GPU's "
                          f"GL_MAX_3D_TEXTURE_SIZE of {limit}")
    if volume.exact_uint8:
        payload = (np.round(volume.data * 255.0).astype(np.uint16) * 257).astype(np.uint16)
        dtype = "nu2"
    else:
        payload = np.ascontiguousarray(volume.data, np.float32)
        dtype = "f4"
    ctx.error  # clear any earlier error flag
    try:
        tex = ctx.texture3d(volume.dims, 1, payload.tobytes(), dtype=dtype, alignment=1)
    except moderngl.Error as exc:
        raise VolumeError(f"{volume.name}: cannot create a {volume.dims} 3D texture ({exc})") from None
    _check_gl(ctx, f"{volume.name} ({payload.nbytes / 2**20:.0f} MiB 3D texture)")
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    tex.repeat_x = tex.repeat_y = tex.repeat_z = False
    return tex


def transfer_texture(ctx: moderngl.Context, table: np.ndarray) -> moderngl.Texture:
    """The RGBA table as an N x 1 RGBA32F texture (read with texelFetch and interpolated exactly)."""
    table = np.ascontiguousarray(table, np.float32)
    tex = ctx.texture((len(table), 1), 4, table.tobytes(), dtype="f4")
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    tex.repeat_x = tex.repeat_y = False
    return tex
