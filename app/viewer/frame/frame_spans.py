"""A viewer frame's deferred spans resolved at its end (RenderSession.step; gl/timer.DeferredSpans):
the frame's one wait for its GPU work, and what it summed from the spans' estimates corrected."""
from __future__ import annotations

import time


def resolve_frame_spans(session, times) -> None:
    """The frame's deferred spans read (the one wait of the frame, for the GPU to finish its
    work), and what was summed from their estimates corrected by their measured ms: the
    frame's bake and render ms, their parts' GPU ms, and each dispatch's entry in the
    pacing's history."""
    notes, session._span_notes = session._span_notes, []
    if not session._spans.pending:
        return
    t = time.perf_counter()
    got = session._spans.resolve()
    session.parts.add("wait", 1e3 * (time.perf_counter() - t))
    for tag, (measured, estimated) in got.items():
        d = measured - estimated
        if tag == "bake":
            times.bake_ms += d
            session.bake_ms += d
            session._bake_turn_ms -= d
            part = times.parts.get("bake")
        elif isinstance(tag, tuple) and tag[0] == "samples":
            times.render_ms += d
            part = times.parts.get("samples")
        else:
            continue
        if part is not None and part[0] is not None:
            part[0] += d
    for tag, entry in notes:
        measured, estimated = got.get(tag, (0.0, 0.0))
        entry[1] += measured - estimated
