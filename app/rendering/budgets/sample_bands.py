"""A sample split into bands over several frames, where one sample of the picture takes longer
than a frame may: the viewer on a software renderer, where one path-traced sample of the foot at
455 x 400 takes 0.5 to 1.5 s of wall time on two cores and one raymarched frame 6 to 19 s. Pure
Python: what a frame does next, from the wall time the bands before it took (the session
dispatches them, Renderer.add_groups).

A band is a run of work groups (tiles of TILE x TILE pixels) in raster order: whole rows of
tiles, with part of a row at either end (tile_rects: three dispatches at most). A band's time is
shared among its tiles in proportion to what they were predicted to cost, so the tiles through
the volume come to cost more than the background's and the next band through them is shorter. A
frame first takes whole samples where no sample is part done and one fits what is left of its
budget; else the next band of the sample in progress, as many tiles as fit (at least one when the
frame has done nothing yet, none more once it has)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

TILE = 8                 # a work group's side in pixels (pathtracer.LOCAL_SIZE)
# A tile not yet timed is predicted at this many times the median of those timed: the background's
# predicted the rows through the foot at a fifth of their time, and a band of them took 176 ms
# against a budget of 40. (The median, not the mean: the first band of a pass pays for its shader's
# compile, on llvmpipe at its first dispatch, 0.8 s for one row of tiles that take 30 ms.)
UNTIMED_FACTOR = 4.0
# ... and at least this many times the tile above it, where that one is timed (bands go in raster
# order, so the row above was timed just before): the raymarcher's tiles through the foot cost
# some 50 times the background's, and its first bands through them took 390 ms against 30.
UNTIMED_ABOVE_FACTOR = 1.5


def tile_grid(width: int, height: int) -> tuple[int, int]:
    """Tiles per row and rows of tiles of an image."""
    return -(-int(width) // TILE), -(-int(height) // TILE)


def tile_rects(tiles_x: int, first: int, end: int) -> list[tuple[int, int, int, int]]:
    """Tiles [first, end) in raster order as rectangles (x0, y0, columns, rows) of tiles: the
    rest of the first row, the whole rows, the start of the last row; none empty."""
    rects = []
    y, x = divmod(first, tiles_x)
    if x:
        n = min(tiles_x - x, end - first)
        rects.append((x, y, n, 1))
        first += n
        y += 1
    rows = (end - first) // tiles_x
    if rows:
        rects.append((0, y, tiles_x, rows))
        first += rows * tiles_x
        y += rows
    if end > first:
        rects.append((0, y, end - first, 1))
    return rects


class TileCosts:
    """Predicted wall ms of each tile of one pass at one image size."""

    def __init__(self, tiles_x: int, tiles_y: int):
        self.tiles_x, self.tiles_y = max(int(tiles_x), 1), max(int(tiles_y), 1)
        self.count = self.tiles_x * self.tiles_y
        self.ms: list[float | None] = [None] * self.count
        self._untimed: float | None = None   # UNTIMED_FACTOR x the timed ones' median, kept
        self._stale = False

    @property
    def known(self) -> bool:
        return self._stale or self._untimed is not None

    def _untimed_ms(self) -> float | None:
        if self._stale:
            timed = sorted(m for m in self.ms if m is not None)
            self._untimed = UNTIMED_FACTOR * timed[len(timed) // 2] if timed else None
            self._stale = False
        return self._untimed

    def _guess(self, tile: int, untimed: float) -> float:
        """An untimed tile's prediction: UNTIMED_FACTOR x the timed ones' median (`untimed`),
        at least UNTIMED_ABOVE_FACTOR x the tile above where that one is timed."""
        above = self.ms[tile - self.tiles_x] if tile >= self.tiles_x else None
        return untimed if above is None else max(untimed, UNTIMED_ABOVE_FACTOR * above)

    def tile_ms(self, tile: int) -> float | None:
        """A tile's predicted ms: its own last one, else a guess from those timed (_guess)."""
        m = self.ms[tile]
        if m is not None:
            return m
        untimed = self._untimed_ms()
        return None if untimed is None else self._guess(tile, untimed)

    def predict(self, first: int, end: int) -> float | None:
        """Predicted ms of tiles [first, end); None while nothing was timed."""
        untimed = self._untimed_ms()
        if untimed is None:
            return None
        return sum(self._guess(t, untimed) if self.ms[t] is None else self.ms[t]
                   for t in range(first, end))

    def sample_ms(self) -> float | None:
        """Predicted ms of a whole sample."""
        return self.predict(0, self.count)

    def observe(self, first: int, end: int, ms: float) -> None:
        """Tiles [first, end) took `ms`, shared among them in proportion to what they were
        predicted to cost (evenly while nothing was known); a tile's prediction rises at once to
        a dearer share and falls halfway to a cheaper one (as the bake's slices do,
        renderer._slice_estimate): on a machine shared with other programs one sample of a
        small picture took 0.6 to 3.4 ms by turns, and following each at once had frames take
        whole samples for 80 ms against a 30 ms budget."""
        untimed = self._untimed_ms()
        weights = [1.0 if untimed is None and self.ms[t] is None else
                   (self.ms[t] if self.ms[t] is not None else self._guess(t, untimed))
                   for t in range(first, end)]
        total = sum(weights)
        for t, w in zip(range(first, end), weights):
            seen = max(float(ms), 0.0) * (w / total if total > 0 else 1.0 / (end - first))
            old = self.ms[t]
            self.ms[t] = seen if old is None or seen >= old else 0.5 * (old + seen)
        self._stale = True

    def plan(self, first: int, budget_ms: float) -> int:
        """The end tile of the next band from `first`: as many tiles as their predictions fit
        in `budget_ms`, at least one (the first of a pass at this size alone: its time pays for
        the compile)."""
        untimed = self._untimed_ms()
        if untimed is None:
            return first + 1
        total, end = 0.0, first
        while end < self.count:
            m = self.ms[end]
            cost = self._guess(end, untimed) if m is None else m
            if end > first and total + cost > budget_ms:
                break
            total += cost
            end += 1
        return end


def next_work(costs: TileCosts, done: int, budget_ms: float, started: bool,
              samples_left: int, most: int = 64) -> tuple[str, int] | None:
    """What a frame with `budget_ms` left of its work does next: ("samples", k), k whole samples
    (no sample part done, and a whole one fits); ("tiles", end), the sample in progress's tiles
    from `done` to `end`; None, nothing (`samples_left` is 0, or the frame has `started` and the
    next tile would overrun what is left). A frame not yet `started` always does something: at
    least one tile."""
    if samples_left <= 0:
        return None
    whole = costs.sample_ms()
    if done == 0 and whole is not None and whole <= budget_ms:
        return "samples", max(1, min(samples_left, most, int(budget_ms // max(whole, 1e-9))))
    if started and (not costs.known or costs.tile_ms(done) > budget_ms):
        return None
    return "tiles", costs.plan(done, budget_ms)


class BandedTarget(Protocol):
    """What a frame's work goes to: an accumulation's counts and the two ways to add to it,
    each returning the wall ms it took (the viewer's view through Renderer.add_samples and
    add_groups; the tests' fake device on a fake clock)."""
    samples: int       # whole samples
    groups_done: int   # tiles of sample samples + 1 done, in raster order

    def add_samples(self, n: int) -> float: ...

    def add_groups(self, end: int) -> float: ...


@dataclass
class FrameWork:
    """What one frame did: its work's ms, the samples it made whole, the tiles it dispatched in
    bands and how many bands."""
    ms: float = 0.0
    samples: int = 0
    tiles: int = 0
    bands: int = 0


def fill_frame(target: BandedTarget, costs: TileCosts, budget_ms: float, max_samples: int,
               most: int = 64, stop: Callable[[], bool] | None = None) -> FrameWork:
    """A frame's work on `target` within `budget_ms`: next_work's steps until it says none or
    `most` samples are whole, each step's ms teaching `costs`; `stop()` true after a step ends
    the frame too (a camera move waiting for a whole sample)."""
    done = FrameWork()
    for _ in range(costs.count + most):   # (the budget ends it sooner)
        started = done.samples > 0 or done.bands > 0
        if done.samples >= most:   # `most` is the frame's, not a step's (a fast frame took 67)
            break
        work = next_work(costs, target.groups_done, budget_ms - done.ms, started,
                         max_samples - target.samples, most - done.samples)
        if work is None:
            break
        kind, amount = work
        if kind == "samples":
            ms = target.add_samples(amount)
            costs.observe(0, costs.count, ms / amount)
            done.samples += amount
        else:
            first = target.groups_done
            ms = target.add_groups(amount)
            costs.observe(first, amount, ms)
            done.tiles, done.bands = done.tiles + amount - first, done.bands + 1
            if target.groups_done == 0:   # that band made its sample whole
                done.samples += 1
        done.ms += ms
        if stop is not None and stop():
            break
    return done
