"""The viewer's error view: its relative RMSE is read back from the GPU about log2(N) times over
an accumulation of N samples (at 1, 2, 4, ... samples and the last), not on every frame."""
from __future__ import annotations

import numpy as np

from radiance_probes.viewer.display import ErrorMeter, sample_stage


class FakeSession:
    def __init__(self):
        self.counts = {"probes": 0, "pt": 0}
        self.restarts = 0
        self.reads = 0

    def samples(self, method):
        return self.counts[method]

    def image(self, method):
        self.reads += 1
        n = max(self.counts[method], 1)
        ref = np.ones((4, 4, 3), np.float32)
        return ref if method == "pt" else ref * (1 + 1 / n)


def test_sample_stage():
    assert [sample_stage(n, 100) for n in (0, 1, 2, 3, 4, 7, 8, 99, 100, 150)] == [
        0, 1, 2, 2, 3, 3, 4, 7, 100, 150]


def test_error_is_measured_again_only_when_the_samples_double_or_finish():
    session, meter = FakeSession(), ErrorMeter()
    values = []
    for frame in range(1, 101):          # both accumulate one sample a frame up to 100
        session.counts = {"probes": frame, "pt": frame}
        values.append(meter.update(session, "probes", max_samples=100))
    assert meter.reads == 8               # 1, 2, 4, 8, 16, 32, 64 and the final 100
    assert session.reads == 2 * meter.reads
    assert meter.samples == (100, 100)
    assert abs(values[-1] - 0.01) < 1e-6  # the last value is the finished images'
    assert abs(values[70] - 1 / 64) < 1e-6  # in between, the value measured at 64 samples
    # a restart (camera moved) measures again at once
    session.restarts += 1
    session.counts = {"probes": 1, "pt": 1}
    assert abs(meter.update(session, "probes", max_samples=100) - 1.0) < 1e-6
    assert meter.reads == 9
