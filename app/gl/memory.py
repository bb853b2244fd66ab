"""Memory the device has left: the NVIDIA driver's own query (GL_NVX_gpu_memory_info) where it
exists, else, on a software renderer whose "GPU memory" is the host's, the host's available memory.
Used to refuse sizes that cannot fit before allocating them, and by the growth test."""
from __future__ import annotations

import ctypes
from pathlib import Path

import moderngl


GPU_MEMORY_INFO_CURRENT_AVAILABLE_VIDMEM_NVX = 0x9049   # KiB

_get_integerv = None


def _gl_get_integer(pname: int) -> int | None:
    global _get_integerv
    if _get_integerv is None:
        from radiance_probes.gl.timer import _lib
        lib = _lib()
        if lib is None:
            return None
        fn = lib.glGetIntegerv
        fn.argtypes = [ctypes.c_uint, ctypes.POINTER(ctypes.c_int)]
        _get_integerv = fn
    value = ctypes.c_int(-1)
    _get_integerv(pname, ctypes.byref(value))
    return value.value if value.value >= 0 else None


def host_available_bytes() -> int | None:
    """MemAvailable of /proc/meminfo, None where there is no such file."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def gpu_available_bytes(ctx: moderngl.Context) -> int | None:
    """The NVIDIA driver's available video memory, None where the driver has no such query."""
    if "GL_NVX_gpu_memory_info" not in ctx.extensions:
        return None
    kib = _gl_get_integer(GPU_MEMORY_INFO_CURRENT_AVAILABLE_VIDMEM_NVX)
    return None if kib is None else kib * 1024


def touch(ctx: moderngl.Context, *buffers) -> None:
    """Gives each buffer (None: skipped) its memory now: zeros copied on the GPU into its first
    4 bytes (a new buffer's contents are undefined, so nothing may read them). The NVIDIA driver
    allocates a buffer made with `reserve` at its first use: in the viewer that was the first
    dispatch of a frame, which then took 17-27 ms longer on the H200 (issue 56)."""
    zero = ctx.buffer(bytes(4))
    for buf in buffers:
        if buf is not None:
            ctx.copy_buffer(buf, zero, 4)
    zero.release()
