"""Streaming a mixed pool's finer level as the camera moves (app/rendering/levels/level_mix.py): the pool's
atlas has every slot the cap allows; the coarser level C is resident whole and stays; the finer
level F's bricks come and go.

    stream = LevelStream(pool)            # a pool made from a mixed PoolPlan (pool.plan)
    stream.restream(camera, budget_s)     # True when the medium changed in this call

restream chooses the bricks of F the camera deserves (level_mix.choose_fine: the rule the
placement uses), compares them with those resident, and:
- evicts F's bricks no longer chosen: their page-table entries go back to REDIRECT | 1 (read C)
  and their slots are freed;
- loads the newly chosen ones, the most deserving first, into free slots: each read once with its
  apron from F's store (BrickStore.resident_layers, as the upload reads them), written to its slot;
  their entries then point at their slots.
The page table changes at a commit, all at once, so that the medium is one between commits: the
loads are written into slots nothing reads, then committed. Where the free slots do not hold the
loads, the evictions are committed first (a medium of fewer F bricks), then the loads. F's
constant bricks read F as constants once F's range pass is read (the first camera that sees a
brick worth a slot reads it; before, they read C), committed with the first commit after.
Texel writes only for what changed. With a budget (seconds) a call writes bricks until it is spent
and the next call goes on (the viewer's frames: app/viewer/viewer.py); a camera that asks for
another mix meanwhile starts over from what is committed (a brick written but not committed is
forgotten, its slot free). The pool never holds more bricks than its slots: at most
`Mix.f_slots` of F, the most deserving (choose_fine).

Each commit changes the medium: the caller (Renderer.restream) recomputes the majorant grid's
density ranges for the new mix (mixed_density_ranges) and treats it as an edit of the medium
(accumulations restart, the probes and the light grid are baked again). A camera that asks for
the mix already held changes nothing: no write, no commit.
"""
from __future__ import annotations

import time

import numpy as np

from radiance_probes.io.brick_layout import CONSTANT, REDIRECT, constant_values
from radiance_probes.rendering.levels.level_mix import choose_fine, footprints, mixed_density_ranges

READ_C = REDIRECT | 1


class _Transition:
    """A restream under way: the target mix, the loads (bricks (z, y, x) -> slot) and their
    reading, and whether the evictions are committed yet."""

    def __init__(self, camera, level_of, const_f, loads: dict, evict: list, reads):
        self.camera = camera
        self.level_of = level_of
        self.const_f = const_f
        self.loads = loads                 # {(z, y, x): slot}, all of them
        self.evict = evict                 # [(z, y, x)] resident now, not wanted
        self.reads = reads                 # BrickStore.resident_layers generator (None: nothing)
        self.written: list = []            # loads written, not committed
        self.evicted = False

    def close(self) -> None:
        if self.reads is not None:
            self.reads.close()             # its readers stopped
            self.reads = None


class LevelStream:
    def __init__(self, pool):
        plan = pool.plan
        self.pool = pool
        self.mix = plan.mix
        self.fine = plan.mix.fine
        self.coarse = plan.mix.coarse
        self.table = plan.table.copy()                    # what the GPU's table holds
        self.level_of = plan.level_of_brick.copy()        # 0: reads F, 1: reads C
        self.const_f = plan.mix.const_f        # F's constant bricks (None: they read C)
        self.bz = self.fine.counts[2]
        top = self.table[:self.bz]
        resident = (top & (CONSTANT | REDIRECT)) == 0
        self.slot_of = {tuple(int(v) for v in b): int(top[tuple(b)])
                        for b in np.argwhere(resident)}
        used = set(self.slot_of.values()) | set(range(self.mix.c_slots))
        self.free = [s for s in range(self.mix.capacity) if s not in used]
        self.camera = None             # the camera the committed mix was chosen for
        self.pending: _Transition | None = None
        # what the stream did (the viewer's status, the benchmark, the tests)
        self.loaded = 0
        self.evicted = 0
        self.commits = 0
        self.last = {}                 # the last restream's counts and seconds

    # ---- what the camera deserves ----------------------------------------------------------
    @property
    def resident(self) -> int:
        """F's bricks in slots now (committed)."""
        return len(self.slot_of)

    def restream(self, camera, budget_s: float | None = None) -> bool:
        """Moves the pool towards the mix `camera` deserves; with `budget_s`, writes bricks for
        about that long and leaves the rest to the next calls. True when a commit changed the
        medium in this call."""
        if self.pending is not None and camera == self.pending.camera:
            return self._advance(budget_s)
        if self.pending is None and camera == self.camera:
            return False
        if self.pending is not None:
            self._abandon()
        start = time.perf_counter()
        level_of, const_f, worth, chosen = choose_fine(self.mix, camera)
        known = const_f is not None and self.const_f is None
        if not known and np.array_equal(level_of, self.level_of):
            self.camera = camera
            self.last = {"evicted": 0, "loaded": 0, "worth": worth, "seconds":
                         time.perf_counter() - start, "commits": 0}
            return False
        chosen = [tuple(int(v) for v in b) for b in chosen]    # nearest the camera first
        want = set(chosen)
        evict = sorted(b for b in self.slot_of if b not in want)
        loads = [b for b in chosen if b not in self.slot_of]
        self.pending = t = _Transition(camera, level_of, const_f, {}, evict, None)
        self.last = {"evicted": len(evict), "loaded": len(loads), "worth": worth,
                     "commits": 0, "started": start}
        committed = False
        if len(loads) > len(self.free):
            # the loads need the evicted bricks' slots: the evictions are committed first
            self._commit(evictions_only=True)
            committed = True
        for b, slot in zip(loads, self.free[:len(loads)]):
            t.loads[b] = slot
        if loads:
            t.reads = self.fine.resident_layers(np.asarray(sorted(loads), np.int64).reshape(-1, 3),
                                                densities=True)
        return self._advance(budget_s) or committed

    # ---- the work -------------------------------------------------------------------------
    def _advance(self, budget_s: float | None) -> bool:
        t = self.pending
        deadline = None if budget_s is None else time.perf_counter() + budget_s
        bx, by, _ = self.fine.counts
        while t.reads is not None:
            try:
                z, (y, x), block = next(t.reads)
            except StopIteration:
                t.reads = None
                break
            slot = t.loads[(z, y, x)]
            self.pool.write_slot(slot, int(x + bx * (y + by * z)), block)
            t.written.append((z, y, x))
            if deadline is not None and time.perf_counter() >= deadline:
                return False
        self._commit()
        return True

    def _commit(self, evictions_only: bool = False) -> None:
        """Writes the page-table entries that change (and the constants where F's range pass
        came to be read): the evictions (and with them F's constants); at the end, the loads."""
        t = self.pending
        new = self.table.copy()
        top = new[:self.bz]
        if not t.evicted:
            for b in t.evict:
                top[b] = READ_C
            if t.const_f is not None and self.const_f is None:
                rows_c = self.pool_constants_c()
                rows_f, which_f = constant_values(self.fine.ranges()[0], t.const_f)
                top[t.const_f] = CONSTANT | (which_f[t.const_f] + len(rows_c))
                self.pool.set_constants(np.concatenate([rows_c, rows_f]))
                self.const_f = t.const_f
        if not evictions_only:
            for b in t.written:
                top[b] = t.loads[b]
        changed = np.argwhere(new != self.table)
        self.pool.write_table([(z, y, x, int(new[z, y, x])) for z, y, x in changed])
        self.table = new
        if not t.evicted:
            freed = [self.slot_of.pop(b) for b in t.evict]
            self.pool.free_slots(freed)
            self.free.extend(freed)
            self.evicted += len(freed)
            t.evicted = True
        if not evictions_only:
            for b in t.written:
                self.slot_of[b] = t.loads[b]
            used = set(t.loads[b] for b in t.written)
            self.free = sorted(s for s in self.free if s not in used)
            self.loaded += len(t.written)
            self.camera = t.camera
            self.pending = None
        else:
            self.free.sort()
        self.level_of = np.where((top & REDIRECT) != 0, 1, 0).astype(np.int64)
        self.commits += 1
        self.last["commits"] = self.last.get("commits", 0) + 1
        if self.pending is None and "started" in self.last:
            self.last["seconds"] = time.perf_counter() - self.last.pop("started")

    def pool_constants_c(self) -> np.ndarray:
        """C's constants' rows (the first rows of the pool's constants)."""
        return constant_values(self.coarse.ranges()[0], self.coarse.constant())[0]

    def _abandon(self) -> None:
        """Forgets a restream under way: what it wrote and did not commit goes (slots free)."""
        t = self.pending
        t.close()
        if t.written:
            self.pool.free_slots([t.loads[b] for b in t.written])
        self.pending = None
        self.last.pop("started", None)

    def cancel(self) -> None:
        if self.pending is not None:
            self._abandon()

    # ---- what the medium is -----------------------------------------------------------------
    def density_ranges(self, cells) -> tuple:
        """The majorant grid's density ranges of the committed mix."""
        return mixed_density_ranges(self.fine, self.coarse, self.level_of, cells)

    def status(self) -> str | None:
        """A line for the viewer's Volume panel while a restream is under way, else None."""
        t = self.pending
        if t is None:
            return None
        return (f"streaming the finer level: {len(t.written)} of {len(t.loads)} bricks loaded, "
                f"{len(t.evict)} evicted")

    def footprints(self, camera) -> np.ndarray:
        return footprints(self.fine.dims, self.fine.brick, self.mix.half_extent, camera)
