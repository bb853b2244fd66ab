"""The device's GL limits that a scene's sizes must fit, checked before anything is allocated, so
a size the device cannot hold ends in one line naming the limit instead of a GL error, a driver
reset or a host MemoryError halfway through a render."""
from __future__ import annotations

import moderngl

from radiance_probes.rendering.methods.pathtracer import PIXEL_STATE_BYTES


class DeviceLimitError(ValueError):
    """A size beyond what this device's OpenGL allows; the message names the GL limit."""


def _limit(ctx: moderngl.Context, name: str, default: int) -> int:
    value = ctx.info.get(name, default)
    if isinstance(value, (tuple, list)):
        value = min(value)
    return int(value)


# Bytes per pixel a render holds: on the device, the path state and the RGBA32F accumulation; on
# the host, the image read back (RGBA float32), its RGB copy and the float64 tone mapping's arrays.
DEVICE_BYTES_PER_PIXEL = PIXEL_STATE_BYTES + 16
HOST_BYTES_PER_PIXEL = 16 + 12 + 4 * 24


def check_image_size(ctx: moderngl.Context, width: int, height: int) -> None:
    """Raises DeviceLimitError unless a width x height image fits this device: its sides within
    GL_MAX_TEXTURE_SIZE and GL_MAX_VIEWPORT_DIMS, the compute dispatch within
    GL_MAX_COMPUTE_WORK_GROUP_COUNT, and its buffers within the memory the device has left (the
    NVIDIA driver's query; on a software renderer, the host's available memory)."""
    from radiance_probes.gl.context import is_software as software_renderer
    from radiance_probes.gl.memory import gpu_available_bytes, host_available_bytes
    from radiance_probes.rendering.methods.pathtracer import LOCAL_SIZE
    side = max(width, height)
    for name in ("GL_MAX_TEXTURE_SIZE", "GL_MAX_VIEWPORT_DIMS"):
        limit = _limit(ctx, name, 16384)
        if side > limit:
            raise DeviceLimitError(f"image {width} x {height}: larger than this device allows "
                                   f"({name} = {limit} pixels per side)")
    groups = _limit(ctx, "GL_MAX_COMPUTE_WORK_GROUP_COUNT", 65535)
    if -(-side // LOCAL_SIZE) > groups:
        raise DeviceLimitError(f"image {width} x {height}: larger than this device allows "
                               f"(GL_MAX_COMPUTE_WORK_GROUP_COUNT = {groups} groups of "
                               f"{LOCAL_SIZE} pixels per side)")
    pixels = width * height
    if software_renderer(ctx):
        need, have = pixels * (DEVICE_BYTES_PER_PIXEL + HOST_BYTES_PER_PIXEL), host_available_bytes()
        where = "host memory available (MemAvailable; a software renderer's GPU memory is the host's)"
    else:
        need, have = pixels * DEVICE_BYTES_PER_PIXEL, gpu_available_bytes(ctx)
        where = "GPU memory available (GL_NVX_gpu_memory_info)"
    if have is not None and need > have:
        raise DeviceLimitError(f"image {width} x {height}: needs about {need / 2**30:.1f} GiB, more "
                               f"than the {have / 2**30:.1f} GiB of {where}")
