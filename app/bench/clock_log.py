"""The GPU's clock over a benchmark run, from nvidia-smi where it exists (OUT/nvidia-smi.csv).

On the lent H100 the SM clock fell to 390-1665 MHz while a probe sweep left the GPU mostly idle
(1980 MHz under load), and the records taken then were slow for no reason of their own
(bench/archive/h100-runs-2). The speed check (ceiling.py) sees the effect; this log names the cause. It
samples every CLOCK_LOG_MS in a process of its own, so the run itself never waits on it. Without
nvidia-smi (llvmpipe, other vendors) nothing is logged and the report says nothing of clocks."""
from __future__ import annotations

import shutil
import statistics
import subprocess
from pathlib import Path

CLOCK_LOG_MS = 500
QUERY = "timestamp,clocks.sm,clocks.max.sm,utilization.gpu"
BELOW = 0.9   # samples under this fraction of the maximum SM clock count as clocked down


class ClockLog:
    def __init__(self, path: Path, executable: str = "nvidia-smi"):
        self.path = Path(path)
        self.executable = shutil.which(executable)
        self._process: subprocess.Popen | None = None
        self._out = None

    def start(self) -> bool:
        """Starts sampling; False where nvidia-smi is absent or does not start."""
        if self.executable is None:
            return False
        self._out = open(self.path, "w")
        try:
            self._process = subprocess.Popen(
                [self.executable, f"--query-gpu={QUERY}", "--format=csv,noheader,nounits",
                 f"--loop-ms={CLOCK_LOG_MS}"], stdout=self._out, stderr=subprocess.DEVNULL)
        except OSError:
            self._out.close()
            self._out = None
            return False
        return True

    def stop(self) -> dict | None:
        """Ends sampling; the summary of what was logged (None: nothing)."""
        if self._process is not None:
            self._process.terminate()
            try:
                self._process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self._process.kill()
            self._process = None
        if self._out is not None:
            self._out.close()
            self._out = None
        return summary(self.path) if self.path.exists() else None


def summary(path: Path) -> dict | None:
    """SM clock over the log: min, median and max MHz, the GPU's maximum, and the fraction of
    samples below BELOW of that maximum (None when no line parses)."""
    clocks, maxima, busy = [], [], []
    for line in Path(path).read_text().splitlines():
        parts = [p.strip() for p in line.split(",")]
        if len(parts) < 4:
            continue
        try:
            clock, most, util = float(parts[1]), float(parts[2]), float(parts[3])
        except ValueError:
            continue
        clocks.append(clock)
        maxima.append(most)
        busy.append(util)
    if not clocks:
        return None
    most = max(maxima)
    return {"samples": len(clocks), "sm_mhz_min": min(clocks),
            "sm_mhz_median": statistics.median(clocks), "sm_mhz_max": max(clocks),
            "sm_mhz_limit": most, "below_fraction": sum(c < BELOW * most for c in clocks) / len(clocks),
            "utilization_median": statistics.median(busy), "every_ms": CLOCK_LOG_MS}


def report_lines(meta: dict) -> list[str]:
    """A sentence for the report's speed section from results.json's meta.gpu_clock."""
    c = meta.get("gpu_clock")
    if not c:
        return []
    return ["", f"nvidia-smi every {c['every_ms']} ms over the run ({c['samples']} samples, "
                f"`nvidia-smi.csv`): SM clock {c['sm_mhz_min']:.0f} to {c['sm_mhz_max']:.0f} MHz, "
                f"median {c['sm_mhz_median']:.0f}, of at most {c['sm_mhz_limit']:.0f}; "
                f"{100 * c['below_fraction']:.0f}% of the samples below {BELOW:.0%} of that; "
                f"GPU busy {c['utilization_median']:.0f}% (median)."]
