"""OpenGL 4.3 core contexts: headless (EGL, then OSMesa, then GLX) and, in the viewer, GLFW.

Headless code imports neither glfw nor imgui. ``create_headless_context("egl"|"osmesa"|"x11")``
(the CLI's ``--gl-backend``) forces one backend; without one, ``RP_GL_BACKEND`` names it (a
shortcut for running a whole test suite on one backend), else they are tried in that order.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import os

import moderngl

GL_VERSION = 430

INSTALL_HINT = (
    "No OpenGL 4.3 context could be made. On Debian/Ubuntu install Mesa's EGL and software "
    "rasteriser: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri libgles2 (or libosmesa6 for "
    "OSMesa); on an NVIDIA machine, the driver's EGL library (libEGL_nvidia). Tried: {tried}"
)


class ContextError(RuntimeError):
    """No OpenGL 4.3 context could be made; the message says what to install."""


def _egl() -> moderngl.Context:
    return moderngl.create_context(standalone=True, backend="egl", require=GL_VERSION)


def _x11() -> moderngl.Context:
    if not os.environ.get("DISPLAY"):
        raise RuntimeError("DISPLAY is not set")
    return moderngl.create_context(standalone=True, require=GL_VERSION)


_osmesa_keepalive: list = []


def _osmesa() -> moderngl.Context:
    name = ctypes.util.find_library("OSMesa") or "libOSMesa.so.8"
    lib = ctypes.CDLL(name)
    OSMESA_FORMAT, OSMESA_RGBA = 0x22, 0x1908
    OSMESA_PROFILE, OSMESA_CORE_PROFILE = 0x33, 0x34
    OSMESA_CONTEXT_MAJOR_VERSION, OSMESA_CONTEXT_MINOR_VERSION = 0x36, 0x37
    attribs = (ctypes.c_int * 9)(OSMESA_FORMAT, OSMESA_RGBA, OSMESA_PROFILE, OSMESA_CORE_PROFILE,
                                 OSMESA_CONTEXT_MAJOR_VERSION, 4, OSMESA_CONTEXT_MINOR_VERSION, 3, 0)
    lib.OSMesaCreateContextAttribs.restype = ctypes.c_void_p
    lib.OSMesaCreateContextAttribs.argtypes = [ctypes.POINTER(ctypes.c_int), ctypes.c_void_p]
    handle = lib.OSMesaCreateContextAttribs(attribs, None)
    if not handle:
        raise RuntimeError("OSMesaCreateContextAttribs failed")
    buf = (ctypes.c_ubyte * (4 * 4 * 4))()
    lib.OSMesaMakeCurrent.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint, ctypes.c_int,
                                      ctypes.c_int]
    if not lib.OSMesaMakeCurrent(handle, buf, 0x1401, 4, 4):
        raise RuntimeError("OSMesaMakeCurrent failed")
    _osmesa_keepalive.append((lib, handle, buf))
    ctx = moderngl.create_context(require=GL_VERSION)
    return ctx


_BACKENDS = {"egl": _egl, "osmesa": _osmesa, "x11": _x11}


BACKENDS = tuple(_BACKENDS)


def create_headless_context(backend: str | None = None) -> moderngl.Context:
    """An OpenGL 4.3 core context with no window, from `backend` (one of BACKENDS) or the first
    that works; raises :class:`ContextError` naming what to install."""
    where = "backend"
    if backend is None and os.environ.get("RP_GL_BACKEND"):
        backend, where = os.environ["RP_GL_BACKEND"], "RP_GL_BACKEND"
    order = [backend] if backend else list(BACKENDS)
    tried = []
    for name in order:
        if name not in _BACKENDS:
            raise ContextError(f"{where} {name!r}: expected one of {', '.join(_BACKENDS)}")
        try:
            ctx = _BACKENDS[name]()
        except Exception as exc:  # each backend fails in its own way
            tried.append(f"{name} ({str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__})")
            continue
        if ctx.version_code < GL_VERSION:
            tried.append(f"{name} (only OpenGL {ctx.version_code})")
            ctx.release()
            continue
        return ctx
    raise ContextError(INSTALL_HINT.format(tried="; ".join(tried)))


def describe(ctx: moderngl.Context) -> str:
    info = ctx.info
    return f"{info.get('GL_RENDERER', '?')} (OpenGL {ctx.version_code})"


# Mesa's llvmpipe (and lavapipe/softpipe) end a SIMD batch's loops after 65535 iterations in all
# (gallivm's loop limiter), counted over the batch, whose lanes diverge: a lane's own count times
# the lanes in a batch must stay below it. The shaders keep their own count and resume in the next
# dispatch. Hardware drivers have no such limit.
SOFTWARE_LOOP_LIMIT = 65535
UNBOUNDED_LOOP_BUDGET = 1 << 30


def loop_budget_unbounded(budget: int) -> bool:
    """True where the driver has no loop limit: a dispatch then runs every path to its end."""
    return budget >= UNBOUNDED_LOOP_BUDGET


def is_software(ctx: moderngl.Context) -> bool:
    """A CPU rasterizer (Mesa's llvmpipe, softpipe, lavapipe)."""
    renderer = ctx.info.get("GL_RENDERER", "").lower()
    return any(name in renderer for name in ("llvmpipe", "softpipe", "lavapipe"))


def loop_budget(ctx: moderngl.Context) -> tuple[int, int]:
    """(loop iterations one invocation may run per dispatch, reserve kept for one more flight)."""
    import re
    renderer = ctx.info.get("GL_RENDERER", "").lower()
    if is_software(ctx):
        m = re.search(r"(\d+) bits", renderer)
        lanes = max(int(m.group(1)) // 32, 1) if m else 16
        budget = SOFTWARE_LOOP_LIMIT // lanes - 256
        return budget, budget // 2
    return UNBOUNDED_LOOP_BUDGET, 0
