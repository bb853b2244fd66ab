"""A sample split into bands of rows over several frames, where one sample of the picture takes
longer than a frame may: the viewer on a software renderer, where one path-traced sample of the
foot at 455 x 400 takes 0.5 to 1.5 s of wall time on two cores. Pure Python: what a frame does
next, from the wall time the bands before it took (the session dispatches, Renderer.add_rows).

A band is a run of whole groups of ROW_GROUP rows (a work group's rows: a dispatch runs whole
groups), and its time is spread over its groups in proportion to what they were predicted to
cost, so the rows through the volume come to cost more than the background's and the next band
through them is shorter. A frame first takes whole samples where no sample is part done and one
fits what is left of its budget; else the next band of the sample in progress, as many groups
as fit (at least one when the frame has done nothing yet, none more once it has)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

ROW_GROUP = 8            # rows one work group covers (pathtracer.LOCAL_SIZE)
# With nothing timed for a pass at an image size, the first band is this share of its groups: its
# time (with a shader compile in it, where the pass is new) then predicts the rest.
FIRST_BAND_SHARE = 8


class RowCosts:
    """Predicted wall ms of each group of ROW_GROUP rows of one pass at one image height."""

    def __init__(self, height: int):
        self.height = max(int(height), 1)
        self.count = -(-self.height // ROW_GROUP)
        self.ms: list[float | None] = [None] * self.count

    def _mean(self) -> float | None:
        known = [m for m in self.ms if m is not None]
        return sum(known) / len(known) if known else None

    @property
    def known(self) -> bool:
        return any(m is not None for m in self.ms)

    def group_ms(self, group: int) -> float | None:
        """A group's predicted ms: its own last one, else the mean of those timed."""
        m = self.ms[group]
        return m if m is not None else self._mean()

    def predict(self, first_row: int, last_row: int) -> float | None:
        """Predicted ms of rows [first_row, last_row); None while nothing was timed."""
        mean = self._mean()
        if mean is None:
            return None
        g0, g1 = first_row // ROW_GROUP, -(-last_row // ROW_GROUP)
        return sum(mean if m is None else m for m in self.ms[g0:g1])

    def sample_ms(self) -> float | None:
        """Predicted ms of a whole sample."""
        return self.predict(0, self.height)

    def observe(self, first_row: int, last_row: int, ms: float) -> None:
        """Rows [first_row, last_row) took `ms`, shared between their groups in proportion to
        what they were predicted to cost (evenly while nothing was known); a group's prediction
        rises at once to a dearer share and falls halfway to a cheaper one (as the bake's slices
        do, renderer._slice_estimate): on a machine shared with other programs one sample of a
        small picture took 0.6 to 3.4 ms by turns, and following each at once had frames take
        whole samples for 80 ms against a 30 ms budget."""
        g0, g1 = first_row // ROW_GROUP, -(-last_row // ROW_GROUP)
        mean = self._mean()
        weights = [1.0 if p is None else p for p in
                   ((self.ms[g] if self.ms[g] is not None else mean) for g in range(g0, g1))]
        total = sum(weights)
        for g, w in zip(range(g0, g1), weights):
            seen = max(float(ms), 0.0) * (w / total if total > 0 else 1.0 / (g1 - g0))
            old = self.ms[g]
            self.ms[g] = seen if old is None or seen >= old else 0.5 * (old + seen)

    def plan(self, first_row: int, budget_ms: float) -> int:
        """The end row of the next band from `first_row`: as many groups as their predictions
        fit in `budget_ms`, at least one; with nothing timed, 1/FIRST_BAND_SHARE of the groups.
        A group not yet timed is a band of its own: the mean of the others predicted the rows
        through the foot at a fifth of their time, and a band of them took 176 ms against 40."""
        g0 = first_row // ROW_GROUP
        if not self.known:
            g1 = g0 + max(1, self.count // FIRST_BAND_SHARE)
        else:
            total, g1 = self.group_ms(g0), g0 + 1
            while (g1 < self.count and self.ms[g0] is not None and self.ms[g1] is not None
                   and total + self.ms[g1] <= budget_ms):
                total += self.ms[g1]
                g1 += 1
        return min(self.height, g1 * ROW_GROUP)


def next_work(costs: RowCosts, rows_done: int, budget_ms: float, started: bool,
              samples_left: int, most: int = 64) -> tuple[str, int] | None:
    """What a frame with `budget_ms` left of its work does next: ("samples", k), k whole samples
    (no sample part done, and a whole one fits); ("rows", end), the sample in progress's rows
    from `rows_done` to `end`; None, nothing (`samples_left` is 0, or the frame has `started`
    and the next group of rows would overrun what is left). A frame not yet `started` always
    does something: at least one group of rows."""
    if samples_left <= 0:
        return None
    whole = costs.sample_ms()
    if rows_done == 0 and whole is not None and whole <= budget_ms:
        return "samples", max(1, min(samples_left, most, int(budget_ms // max(whole, 1e-9))))
    if started and (not costs.known or costs.group_ms(rows_done // ROW_GROUP) > budget_ms):
        return None
    return "rows", costs.plan(rows_done, budget_ms)


class BandedTarget(Protocol):
    """What a frame's work goes to: an accumulation's counts and the two ways to add to it,
    each returning the wall ms it took (the viewer's view through Renderer.add_samples and
    add_rows; the tests' fake device on a fake clock)."""
    samples: int      # whole samples
    rows_done: int    # rows of sample samples + 1 done

    def add_samples(self, n: int) -> float: ...

    def add_rows(self, end: int) -> float: ...


@dataclass
class FrameWork:
    """What one frame did: its work's ms, the samples it made whole, the rows it dispatched in
    bands and how many bands."""
    ms: float = 0.0
    samples: int = 0
    rows: int = 0
    bands: int = 0


def fill_frame(target: BandedTarget, costs: RowCosts, budget_ms: float, max_samples: int,
               most: int = 64, stop: Callable[[], bool] | None = None) -> FrameWork:
    """A frame's work on `target` within `budget_ms`: next_work's steps until it says none, each
    step's ms teaching `costs`; `stop()` true after a step ends the frame too (a camera move
    waiting for a whole sample)."""
    done = FrameWork()
    for _ in range(4 * costs.count + most):   # (the budget ends it sooner)
        started = done.samples > 0 or done.bands > 0
        work = next_work(costs, target.rows_done, budget_ms - done.ms, started,
                         max_samples - target.samples, most)
        if work is None:
            break
        kind, amount = work
        if kind == "samples":
            ms = target.add_samples(amount)
            costs.observe(0, costs.height, ms / amount)
            done.samples += amount
        else:
            first = target.rows_done
            ms = target.add_rows(amount)
            costs.observe(first, amount, ms)
            done.rows, done.bands = done.rows + amount - first, done.bands + 1
            if target.rows_done == 0:   # that band made its sample whole
                done.samples += 1
        done.ms += ms
        if stop is not None and stop():
            break
    return done
