"""How long one dispatch may run. A GPU that also drives a display resets its driver when one
dispatch runs for seconds (Windows' watchdog fires at 2 s), and a GPU 20x slower than the H100
turns a 100 ms dispatch into 2 s; so every pass that can grow with the settings (the path-state
passes' samples and image size, the bake's walk chunks) is cut into dispatches of at most
DISPATCH_TARGET_MS by what the same pass measured on this device, and the bench records each
run's longest dispatch (app/gl/dispatch_log.py) against DISPATCH_BOUND_MS.

On a software rasteriser (llvmpipe) everything runs about three thousand times slower than on the
H100 and its driver has no watchdog: nothing is cut there (its loop limit already ends each
invocation's work per dispatch), and the bound scales with its measured speed (device_slowdown,
which the tests measure; it runs a march of its own, so it is never called on a hot path)."""
from __future__ import annotations

import math
import weakref

from radiance_probes.gl.context import is_software

DISPATCH_BOUND_MS = 50.0    # no dispatch longer than this on the H100, at any setting offered
DISPATCH_TARGET_MS = 15.0   # what the cutting aims at: estimates come from earlier dispatches
                            # of the same pass, and the next one's work may differ by 3x (20 ms
                            # gave bake chunks of up to 115 ms on the battery's shells)
# The speed check's GPU ms on the H100 (app/rendering/budgets/ceiling.py speed_check_ms: 2^18 rays x 64
# trilinear steps; bench/h100 records, median over the run: 0.171 ms).
H100_SPEED_CHECK_MS = 0.171
CALIBRATION_RAYS = 1 << 14   # a sixteenth of the speed check's rays, scaled up

_slowdown: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def device_slowdown(renderer) -> float:
    """How many times slower than the H100 this device runs the speed check's march: 1 on a GPU
    (a dispatch's time is measured on the device itself, and the watchdog counts wall time), the
    measured ratio on a software rasteriser (cached per context)."""
    ctx = renderer.ctx
    if not is_software(ctx):
        return 1.0
    if ctx not in _slowdown:
        from radiance_probes.rendering.budgets.ceiling import (SPEED_CHECK_RAYS, SPEED_CHECK_STEPS,
                                                               measure_ceiling)
        ms = measure_ceiling(renderer, CALIBRATION_RAYS, SPEED_CHECK_STEPS, repeats=1)["ms"]
        _slowdown[ctx] = max(1.0, ms * (SPEED_CHECK_RAYS / CALIBRATION_RAYS) / H100_SPEED_CHECK_MS)
    return _slowdown[ctx]


def dispatch_target_ms(renderer) -> float:
    """What the cutting aims at on this device: DISPATCH_TARGET_MS on a GPU, nothing on a CPU
    rasteriser (infinite)."""
    return math.inf if is_software(renderer.ctx) else DISPATCH_TARGET_MS


def dispatch_bound_ms(renderer) -> float:
    return DISPATCH_BOUND_MS * device_slowdown(renderer)
