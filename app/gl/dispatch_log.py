"""GPU time of every compute dispatch, while a DispatchLog is active: what the bench records as a
run's longest dispatch (a driver that also draws the desktop resets itself when one dispatch runs
for seconds: Windows' watchdog fires at 2 s).

Each dispatch of a ComputeProgram (app/gl/shaders.py) is bracketed by two timestamps in the
command stream (glQueryCounter), so recording adds no host round trip while the work runs; the
results are read when asked for (`take`), by which time the caller has usually waited for the GPU
anyway (an image read back). Only one log is active at a time (`with DispatchLog() as log:`).
On a software rasteriser (llvmpipe), whose timestamps are taken late (app/gl/timer.py), each
dispatch is timed on the host instead, between two glFinish calls.
"""
from __future__ import annotations

import ctypes
import time

from radiance_probes.gl.context import is_software

from radiance_probes.gl.timer import GL_QUERY_RESULT, GL_TIMESTAMP, _lib

_ACTIVE: list["DispatchLog"] = []


def active_log() -> "DispatchLog | None":
    return _ACTIVE[-1] if _ACTIVE else None


class DispatchLog:
    def __init__(self):
        self._gl = _lib()
        self._pending: list[tuple[str, int, int]] = []   # (program, start query, end query)
        self._host: list[tuple[str, float]] = []          # (program, ms) timed on the host
        self.longest_ms = 0.0
        self.longest_name = None
        self.dispatches = 0

    @property
    def available(self) -> bool:
        return self._gl is not None

    def __enter__(self) -> "DispatchLog":
        _ACTIVE.append(self)
        return self

    def __exit__(self, *exc) -> bool:
        _ACTIVE.remove(self)
        return False

    def begin(self, ctx=None):
        if ctx is not None and is_software(ctx):
            ctx.finish()
            return ("host", ctx, time.perf_counter())
        if self._gl is None:
            return None
        q = (ctypes.c_uint * 2)()
        self._gl.glGenQueries(2, q)
        self._gl.glQueryCounter(q[0], GL_TIMESTAMP)
        return (q[0], q[1])

    def end(self, name: str, queries) -> None:
        if queries is None:
            return
        if queries[0] == "host":
            queries[1].finish()
            self._host.append((name, 1e3 * (time.perf_counter() - queries[2])))
            self.dispatches += 1
            return
        self._gl.glQueryCounter(queries[1], GL_TIMESTAMP)
        self._pending.append((name, queries[0], queries[1]))
        self.dispatches += 1

    def _resolve(self) -> list[tuple[str, float]]:
        out, self._host = self._host, []
        for name, start, end in self._pending:
            a, b = ctypes.c_uint64(), ctypes.c_uint64()
            self._gl.glGetQueryObjectui64v(start, GL_QUERY_RESULT, ctypes.byref(a))
            self._gl.glGetQueryObjectui64v(end, GL_QUERY_RESULT, ctypes.byref(b))
            out.append((name, (b.value - a.value) / 1e6))
            ids = (ctypes.c_uint * 2)(start, end)
            self._gl.glDeleteQueries(2, ids)
        self._pending.clear()
        return out

    def take(self) -> tuple[float, str | None]:
        """The longest dispatch since the last take (GPU ms, program name), waiting for the GPU
        where results are not in yet; the log's overall longest is kept in longest_ms."""
        best, best_name = 0.0, None
        for name, ms in self._resolve():
            if ms > best:
                best, best_name = ms, name
        if best > self.longest_ms:
            self.longest_ms, self.longest_name = best, best_name
        return best, best_name
