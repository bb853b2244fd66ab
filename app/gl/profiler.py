"""GPU time per named section of a sequence of passes, from OpenGL timestamp queries.

Each section's start and end are timestamps written into the command stream (glQueryCounter), so
profiling adds no host round trip while the work runs; the results are read once, at the end.
Used by the benchmark's bake profile (walks, projection, the sun's transmittance).
"""
from __future__ import annotations

import ctypes
from contextlib import contextmanager

from radiance_probes.gl.timer import GL_QUERY_RESULT, GL_TIMESTAMP, _lib


class GpuProfile:
    def __init__(self):
        self._gl = _lib()
        self._spans: list[tuple[str, int, int]] = []   # (section, start query, end query)
        self._queries: list[int] = []

    @property
    def available(self) -> bool:
        return self._gl is not None

    def _query(self) -> int:
        q = ctypes.c_uint()
        self._gl.glGenQueries(1, ctypes.byref(q))
        self._queries.append(q.value)
        return q.value

    @contextmanager
    def section(self, name: str):
        if self._gl is None:
            yield
            return
        start, end = self._query(), self._query()
        self._gl.glQueryCounter(start, GL_TIMESTAMP)
        try:
            yield
        finally:
            self._gl.glQueryCounter(end, GL_TIMESTAMP)
            self._spans.append((name, start, end))

    def totals_ms(self) -> dict[str, float]:
        """GPU ms per section, summed over its spans (waits for the GPU once)."""
        out: dict[str, float] = {}
        for name, start, end in self._spans:
            a, b = ctypes.c_uint64(), ctypes.c_uint64()
            self._gl.glGetQueryObjectui64v(start, GL_QUERY_RESULT, ctypes.byref(a))
            self._gl.glGetQueryObjectui64v(end, GL_QUERY_RESULT, ctypes.byref(b))
            out[name] = out.get(name, 0.0) + (b.value - a.value) / 1e6
        return out

    def spans(self, name: str) -> int:
        return sum(1 for n, _, _ in self._spans if n == name)

    def release(self) -> None:
        if self._gl is not None and self._queries:
            ids = (ctypes.c_uint * len(self._queries))(*self._queries)
            self._gl.glDeleteQueries(len(self._queries), ids)
        self._queries, self._spans = [], []
