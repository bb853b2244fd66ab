"""A private X server (Xvfb) for running the viewer where there is no display: scripted
screenshots, CI, the tests. Imports neither glfw nor imgui."""
from __future__ import annotations

import os
import select
import shutil
import subprocess
import tempfile
import time

START_TIMEOUT_SECONDS = 15.0


class XvfbError(RuntimeError):
    pass


def has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


class Xvfb:
    """``with Xvfb() as display: ...`` starts Xvfb on a free display number (-displayfd) and
    stops it on exit; ``display`` is ':N'."""

    def __init__(self, width: int = 1280, height: int = 800, depth: int = 24):
        self.size = (width, height, depth)
        self.process: subprocess.Popen | None = None
        self.display: str | None = None
        self.log = None

    def start(self) -> str:
        exe = shutil.which("Xvfb") or ("/usr/bin/Xvfb" if os.path.exists("/usr/bin/Xvfb") else None)
        if exe is None:
            raise XvfbError("Xvfb is not installed (apt-get install xvfb)")
        read_fd, write_fd = os.pipe()
        w, h, d = self.size
        self.log = tempfile.TemporaryFile()
        try:
            self.process = subprocess.Popen(
                [exe, "-displayfd", str(write_fd), "-screen", "0", f"{w}x{h}x{d}", "-nolisten", "tcp",
                 "-noreset"], pass_fds=(write_fd,), stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL, stderr=self.log)
        finally:
            os.close(write_fd)
        # Xvfb writes the number and a newline, maybe in two writes; closing the pipe before the
        # newline arrives kills it ("Cannot write display number").
        reply = b""
        deadline = time.monotonic() + START_TIMEOUT_SECONDS
        try:
            while not reply.endswith(b"\n") and time.monotonic() < deadline:
                ready, _, _ = select.select([read_fd], [], [], max(deadline - time.monotonic(), 0))
                chunk = os.read(read_fd, 64) if ready else b""
                if not chunk:
                    break
                reply += chunk
        finally:
            os.close(read_fd)
        number = reply.decode().strip()
        if not number.isdigit():
            self.stop()
            raise XvfbError(f"Xvfb did not start: {self.log_tail() or 'no display number reported'}")
        self.display = f":{number}"
        return self.display

    def log_tail(self, n: int = 600) -> str:
        if self.log is None:
            return ""
        self.log.seek(0)
        return self.log.read().decode(errors="replace")[-n:].strip()

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.process = None

    def __enter__(self) -> str:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
