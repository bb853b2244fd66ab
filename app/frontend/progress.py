"""A progress bar on stderr for long work (a movie's frames): redrawn in place on a terminal,
a line every tenth of the way otherwise (logs, CI)."""
from __future__ import annotations

import sys
import time

BAR_WIDTH = 30


class ProgressBar:
    def __init__(self, label: str, total: int, unit: str = "frames", stream=None):
        self.label, self.total, self.unit = label, max(int(total), 1), unit
        self.stream = stream if stream is not None else sys.stderr
        self.interactive = getattr(self.stream, "isatty", lambda: False)()
        self.start = time.perf_counter()
        self._last_tenth = -1

    def text(self, done: int) -> str:
        frac = min(max(done / self.total, 0.0), 1.0)
        filled = int(round(frac * BAR_WIDTH))
        elapsed = time.perf_counter() - self.start
        rate = done / elapsed if elapsed > 0 else 0.0
        left = (self.total - done) / rate if rate > 0 else float("nan")
        eta = f", {left:.0f} s left" if done < self.total and rate > 0 else f", {elapsed:.1f} s"
        speed = (f"{rate:.1f} {self.unit}/s" if rate >= 1 or rate == 0 else
                 f"{1 / rate:.1f} s per {self.unit.rstrip('s')}")
        return (f"{self.label} [{'#' * filled}{'.' * (BAR_WIDTH - filled)}] {done}/{self.total} "
                f"{self.unit} ({100 * frac:.0f}%), {speed}{eta}")

    def update(self, done: int) -> None:
        if self.interactive:
            end = "\n" if done >= self.total else ""
            print("\r" + self.text(done), end=end, file=self.stream, flush=True)
            return
        tenth = int(10 * done / self.total)
        if tenth != self._last_tenth or done >= self.total:
            self._last_tenth = tenth
            print(self.text(done), file=self.stream, flush=True)
