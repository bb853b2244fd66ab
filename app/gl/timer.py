"""GPU time from OpenGL timestamp queries (glQueryCounter), never a CPU clock around GPU work.

moderngl exposes only GL_TIME_ELAPSED queries, which Mesa's llvmpipe does not fill for compute
dispatches; timestamps work on llvmpipe and NVIDIA alike, so we call glQueryCounter through the
GLVND dispatch library (libOpenGL), which forwards to whatever context is current (EGL or GLX).
"""
from __future__ import annotations

import ctypes
import ctypes.util

GL_TIMESTAMP = 0x8E28
GL_QUERY_RESULT = 0x8866
GL_FRAMEBUFFER = 0x8D40

_gl = None


def _lib():
    global _gl
    if _gl is None:
        for name in (ctypes.util.find_library("OpenGL"), "libOpenGL.so.0", ctypes.util.find_library("GL"),
                     "libGL.so.1"):
            if not name:
                continue
            try:
                lib = ctypes.CDLL(name)
                lib.glQueryCounter  # noqa: B018 (raises AttributeError when missing)
            except (OSError, AttributeError):
                continue
            lib.glGenQueries.argtypes = [ctypes.c_int, ctypes.POINTER(ctypes.c_uint)]
            lib.glDeleteQueries.argtypes = [ctypes.c_int, ctypes.POINTER(ctypes.c_uint)]
            lib.glQueryCounter.argtypes = [ctypes.c_uint, ctypes.c_uint]
            lib.glGetQueryObjectui64v.argtypes = [ctypes.c_uint, ctypes.c_uint,
                                                  ctypes.POINTER(ctypes.c_uint64)]
            lib.glBindFramebuffer.argtypes = [ctypes.c_uint, ctypes.c_uint]
            lib.glFlush.argtypes = []
            _gl = lib
            break
        else:
            _gl = False
    return _gl or None


def _span_ms(gl, start: int, end: int) -> float:
    """GPU ms between two timestamp queries' results (waits for them)."""
    a, b = ctypes.c_uint64(), ctypes.c_uint64()
    gl.glGetQueryObjectui64v(start, GL_QUERY_RESULT, ctypes.byref(a))
    gl.glGetQueryObjectui64v(end, GL_QUERY_RESULT, ctypes.byref(b))
    return (b.value - a.value) / 1e6


class Timer:
    """What the renderers time work with: start(), stop(), then elapsed_ms; a `with` block brackets
    the work the same way; release() frees what it holds. GpuTimer (timestamps) and WallTimer (the
    wall clock, where timestamps cannot be believed) are the two."""

    available = True

    def start(self) -> None:
        raise NotImplementedError

    def stop(self) -> None:
        raise NotImplementedError

    @property
    def elapsed_ms(self) -> float:
        raise NotImplementedError

    def release(self) -> None:
        pass

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.stop()


class GpuTimer(Timer):
    """Brackets GPU work with two timestamps; ``elapsed_ms`` waits for the result.

    >>> t = GpuTimer(); t.start(); ...dispatch...; t.stop(); t.elapsed_ms
    Falls back to moderngl's GL_TIME_ELAPSED query when libOpenGL is not available.

    On a software rasteriser (llvmpipe) a timestamp is binned into the rasteriser's pending scene
    and taken when that scene runs, after the compute work it should bracket; binding another
    framebuffer flushes the scene. So on those, start() binds a 1x1 framebuffer of its own and
    then the framebuffer it found (its viewport with it): callers see no change of binding.
    """

    def __init__(self, ctx=None):
        self._gl = _lib()
        self._ctx = ctx
        self._flush_fbo = None
        if ctx is not None:
            renderer = ctx.info.get("GL_RENDERER", "").lower()
            if any(name in renderer for name in ("llvmpipe", "softpipe", "lavapipe")):
                self._flush_fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((1, 1), 4)])
        self._fallback = None
        if self._gl is not None:
            self._ids = (ctypes.c_uint * 2)()
            self._gl.glGenQueries(2, self._ids)
        elif ctx is not None:
            self._fallback = ctx.query(time=True)
        self._running = False

    @property
    def available(self) -> bool:
        return self._gl is not None or self._fallback is not None

    def _flush_rasteriser(self) -> None:
        found = self._ctx.fbo
        if found is not None and type(found.mglo).__name__ == "InvalidObject":
            found = None   # the caller released the framebuffer it last used
        self._flush_fbo.use()
        if found is not None:
            found.use()
        elif self._gl is not None:   # a standalone context before any framebuffer was used
            self._gl.glBindFramebuffer(GL_FRAMEBUFFER, 0)
            self._ctx.fbo = None

    def start(self) -> None:
        if self._flush_fbo is not None:
            self._flush_rasteriser()
        if self._gl is not None:
            self._gl.glQueryCounter(self._ids[0], GL_TIMESTAMP)
        elif self._fallback is not None:
            self._fallback.__enter__()
        self._running = True

    def stop(self) -> None:
        if self._gl is not None:
            self._gl.glQueryCounter(self._ids[1], GL_TIMESTAMP)
        elif self._fallback is not None:
            self._fallback.__exit__(None, None, None)
        self._running = False

    @property
    def elapsed_ms(self) -> float:
        if self._gl is not None:
            return _span_ms(self._gl, self._ids[0], self._ids[1])
        if self._fallback is not None:
            return self._fallback.elapsed / 1e6
        return float("nan")

    def release(self) -> None:
        if self._gl is not None:
            self._gl.glDeleteQueries(2, self._ids)
            self._gl = None
        if self._fallback is not None:
            self._fallback.release()
            self._fallback = None
        if self._flush_fbo is not None:
            for attachment in self._flush_fbo.color_attachments:
                attachment.release()
            self._flush_fbo.release()
            self._flush_fbo = None


GL_QUERY_RESULT_AVAILABLE = 0x8867


class SpanClock:
    """GPU time of spans of work read without waiting: `start()`/`stop(units)` bracket a span with
    timestamps, and `poll()` returns the GPU ms per unit of the newest span whose result is in
    (None while none is), never blocking. For sizing the next dispatch from the last ones while
    the GPU stays busy (ProbeGrid's walk chunks). Needs libOpenGL (timestamps); on a software
    rasteriser its spans would be binned late, so callers use it on GPUs only."""

    def __init__(self):
        self._gl = _lib()
        self._open = None
        self._spans: list[tuple[int, int, float]] = []   # (start query, end query, units)

    @property
    def available(self) -> bool:
        return self._gl is not None

    def start(self) -> None:
        if self._gl is None:
            return
        q = (ctypes.c_uint * 2)()
        self._gl.glGenQueries(2, q)
        self._gl.glQueryCounter(q[0], GL_TIMESTAMP)
        self._open = (q[0], q[1])

    def stop(self, units: float) -> None:
        if self._gl is None or self._open is None:
            return
        self._gl.glQueryCounter(self._open[1], GL_TIMESTAMP)
        self._spans.append((*self._open, float(units)))
        self._open = None

    def poll(self) -> float | None:
        """GPU ms per unit of the newest finished span (older finished ones are dropped)."""
        newest = None
        while self._spans:
            start, end, units = self._spans[0]
            ready = ctypes.c_uint64()
            self._gl.glGetQueryObjectui64v(end, GL_QUERY_RESULT_AVAILABLE, ctypes.byref(ready))
            if not ready.value:
                break
            ms = _span_ms(self._gl, start, end)
            self._gl.glDeleteQueries(2, (ctypes.c_uint * 2)(start, end))
            self._spans.pop(0)
            newest = ms / max(units, 1e-9)
        return newest

    def release(self) -> None:
        if self._gl is None:
            return
        for start, end, _ in self._spans:
            self._gl.glDeleteQueries(2, (ctypes.c_uint * 2)(start, end))
        self._spans.clear()


class WallTimer(Timer):
    """The wall clock from start() to the end of the work between start() and stop() (a glFinish
    at each end, so that work queued before is not counted and work queued between is): the
    viewer's timer where GPU timestamps cannot be believed (app/viewer/frame/pacing.py). Holds the GPU
    timer it replaces, released with it."""

    def __init__(self, ctx, replaces=None):
        import time
        self._clock = time.perf_counter
        self._ctx = ctx
        self.replaces = replaces
        self._start = self._stop = 0.0

    def start(self) -> None:
        self._ctx.finish()
        self._start = self._clock()

    def stop(self) -> None:
        self._ctx.finish()
        self._stop = self._clock()

    @property
    def elapsed_ms(self) -> float:
        return 1000.0 * (self._stop - self._start)

    def release(self) -> None:
        if self.replaces is not None:
            self.replaces.release()
            self.replaces = None


class DeferredSpans:
    """GPU spans of a frame whose timestamps are read once, at the frame's end, instead of after
    each dispatch (issue 56: on the H200 at 1080p a refine frame waited 4 to 6 times for its
    timers, and its 4.5-5 ms of host work ran while the GPU stood idle, so its wall time was its
    GPU time plus all of that; lab/experiments/frame_host_profile.py). A caller that needs a span's
    ms at once gets its own estimate back (`stop`); `resolve()` waits for the GPU once, reads every
    span, runs each span's `on_done(ms)` (what the estimate was made from learns the measured
    time) and returns, per tag, (measured ms, estimated ms), so that the caller corrects what it
    summed from the estimates. Spans are GpuTimers (llvmpipe's flush included), kept for reuse."""

    def __init__(self, ctx):
        self._ctx = ctx
        self._gl = _lib()
        self._free: list[GpuTimer] = []
        self._open: list[tuple[GpuTimer, object, float, object]] = []   # timer, tag, estimate, on_done
        self.tag: object = None    # the tag of spans begun from now on (the caller's)

    def start(self) -> GpuTimer:
        timer = self._free.pop() if self._free else GpuTimer(self._ctx)
        timer.start()
        return timer

    def stop(self, timer: GpuTimer, estimate_ms: float, on_done=None, tag=None) -> float:
        """Ends the span begun by `start` and returns `estimate_ms` (its time is read later).
        `tag`: the span's own (a span inside another's, not to be summed with it), else self.tag."""
        timer.stop()
        self._open.append((timer, self.tag if tag is None else tag, float(estimate_ms), on_done))
        # the span's work handed to the GPU now: a driver holds commands in its buffer until a
        # flush, and with no wait after the span nothing else would send them (on the H200 the
        # deferred frame's GPU started at its end-of-frame wait, its host work not overlapped)
        if self._gl is not None:
            self._gl.glFlush()
        return float(estimate_ms)

    @property
    def pending(self) -> int:
        return len(self._open)

    def resolve(self) -> dict:
        """{tag: (measured ms, estimated ms)} over the spans since the last resolve (waits for
        the newest span's end: the GPU has then done all of them)."""
        out: dict = {}
        spans, self._open = self._open, []
        for timer, tag, estimate, on_done in spans:
            ms = timer.elapsed_ms
            if on_done is not None:
                on_done(ms)
            measured, estimated = out.get(tag, (0.0, 0.0))
            out[tag] = (measured + ms, estimated + estimate)
            self._free.append(timer)
        return out

    def release(self) -> None:
        for timer, *_ in self._open:
            timer.release()
        for timer in self._free:
            timer.release()
        self._open, self._free = [], []
