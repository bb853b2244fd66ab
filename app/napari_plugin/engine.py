"""The plugin's renderer in a process of its own (no Qt, no napari): one radiance_probes.Renderer
whose GL context is made, used and released on that process's render thread alone, fed the
latest request (a newer one replaces one not yet started; a running refinement stops at its next
round). A process, not a thread of napari's: moderngl holds Python's lock through its GL calls
(measured on llvmpipe: the main thread stalled 100 ms at a time while a thread rendered), which
would freeze napari's event loop; another process leaves it free.

A request is a scene (array and options, as radiance_probes.render takes them) and a camera. The
thread first draws the raymarcher's image at the preview size (while the camera moves), then,
if the request is still the latest, refines: the chosen method's image at full size in rounds of
`spp_per_round` samples, each round a new seed, the rounds averaged, and the estimated error of
the mean from its two halves (even and odd rounds: the mean's rRMSE is about
rms(even - odd) / 2 / rms(mean)), until `max_samples`; then the denoiser where asked. A
deterministic method (the raymarcher) and a composite one (refine) are one render of
`max_samples` samples. Each image comes back as a Frame to `deliver(Frame)`, called on a thread
of napari's process that only waits on the pipe (a Qt caller passes it on through a signal).
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from radiance_probes.methods import METHODS as REGISTRY

PREVIEW_SPP = 1          # the raymarcher's frames per preview image
WORKER_START_SECONDS = 60.0   # the worker process connects back within this


@dataclass
class Request:
    data: np.ndarray
    options: dict                 # scene options (render()'s keywords), the camera left out
    camera: dict                  # our camera (camera_map.napari_to_camera)
    method: str = "raymarch"
    max_samples: int = 4
    denoise: bool = False
    seed: int = 0
    preview_scale: float = 0.5    # the preview's size against the camera's
    spp_per_round: int = 1
    serial: int = 0               # set by the engine
    data_token: int = 0           # which array (sent to the worker once; set by the engine)


@dataclass
class Frame:
    image: np.ndarray             # linear RGB (H, W, 3), float32, row 0 at the top
    serial: int
    stage: str                    # "preview", "refining", "done"
    method: str
    samples: int
    max_samples: int
    error: float | None = None    # estimated rRMSE of the mean (None: not estimated)
    denoised: bool = False
    ms: float = 0.0
    notes: tuple[str, ...] = field(default=())

    @property
    def progress(self) -> float:
        return min(self.samples / max(self.max_samples, 1), 1.0)


def half_error(even: np.ndarray, odd: np.ndarray, mean: np.ndarray) -> float | None:
    """The estimated rRMSE of `mean` = (even + odd) / 2 (module docstring)."""
    ref = float(np.sqrt(np.mean(np.square(mean, dtype=np.float64))))
    if not ref > 0:
        return None
    return float(np.sqrt(np.mean(np.square(even - odd, dtype=np.float64)))) / 2.0 / ref


def scaled_camera(camera: dict, scale: float) -> dict:
    w = max(8, int(round(camera["width"] * scale)))
    h = max(8, int(round(camera["height"] * scale)))
    return {**camera, "width": w, "height": h}


class _Server:
    """The worker process's side: the latest request, served on its render thread."""

    def __init__(self, deliver, on_error, gl_backend: str | None = None):
        self._deliver = deliver
        self._on_error = on_error
        self._gl_backend = gl_backend
        self._lock = threading.Condition()
        self._pending: Request | None = None
        self._serial = 0
        self._closing = False
        self._renderer = None
        self._renderer_key = None
        self.busy = False
        self.renders = 0            # images rendered so far (previews and rounds)
        self._thread = threading.Thread(target=self._run, name="radiance-probes-napari",
                                        daemon=True)
        self._thread.start()

    def submit_as(self, request: Request) -> None:
        """The latest request, its serial as the engine numbered it."""
        with self._lock:
            self._serial = request.serial
            self._pending = request
            self._lock.notify_all()

    def close(self, timeout: float = 30.0) -> None:
        with self._lock:
            self._closing = True
            self._pending = None
            self._lock.notify_all()
        self._thread.join(timeout)

    # ---- the render thread ------------------------------------------------------------------------
    def _superseded(self, request: Request) -> bool:
        return self._closing or self._serial != request.serial

    def _run(self) -> None:
        try:
            while True:
                with self._lock:
                    while self._pending is None and not self._closing:
                        self._lock.wait()
                    if self._closing:
                        return
                    request, self._pending = self._pending, None
                    self.busy = True
                try:
                    self._serve(request)
                except Exception as exc:   # a message in the widget, never a traceback
                    self._forget()
                    self._on_error(f"{type(exc).__name__}: {exc}" if not str(exc) else str(exc))
                finally:
                    with self._lock:
                        self.busy = False
        finally:
            self._forget()

    def _forget(self) -> None:
        if self._renderer is not None:
            try:
                self._renderer.close()
            finally:
                self._renderer, self._renderer_key = None, None

    def _renderer_for(self, request: Request):
        import json
        from radiance_probes.api.render import Renderer
        key = (request.data_token, json.dumps(request.options, sort_keys=True))
        if self._renderer is None or self._renderer_key != key:
            self._forget()
            self._renderer = Renderer(request.data, gl_backend=self._gl_backend,
                                      **request.options)
            self._renderer_key = key
        return self._renderer

    def _render(self, request: Request, method: str, spp: int, camera: dict, seed: int,
                denoise: bool = False):
        r = self._renderer_for(request)
        image = r.render(method, spp, camera=camera, seed=seed, denoise=denoise)
        self.renders += 1
        return image

    def _serve(self, request: Request) -> None:
        start = time.perf_counter()
        full = request.camera
        if request.preview_scale < 1.0:
            img = self._render(request, "raymarch", PREVIEW_SPP,
                               scaled_camera(full, request.preview_scale), request.seed)
            self._deliver(Frame(img.linear, request.serial, "preview", "raymarch", PREVIEW_SPP,
                                request.max_samples, ms=1e3 * (time.perf_counter() - start),
                                notes=img.notes))
            if self._superseded(request):
                return
        method = REGISTRY[request.method]
        if not method.noisy or method.composite:
            img = self._render(request, request.method, request.max_samples, full, request.seed,
                               denoise=request.denoise and method.noisy)
            denoised = request.denoise and method.noisy and not any(
                "denois" in n for n in img.notes[len(self._renderer.notes):])
            self._deliver(Frame(img.linear, request.serial, "done", request.method,
                                request.max_samples, request.max_samples, denoised=denoised,
                                ms=1e3 * (time.perf_counter() - start), notes=img.notes))
            return
        sums = [None, None]
        counts = [0, 0]
        done = 0
        rounds = 0
        per = max(1, int(request.spp_per_round))
        while done < request.max_samples:
            spp = min(per, request.max_samples - done)
            img = self._render(request, request.method, spp, full, request.seed + rounds)
            half = rounds % 2
            weighted = img.linear.astype(np.float64) * spp
            sums[half] = weighted if sums[half] is None else sums[half] + weighted
            counts[half] += spp
            done += spp
            rounds += 1
            mean = sum(s for s in sums if s is not None) / done
            error = (half_error(sums[0] / counts[0], sums[1] / counts[1], mean)
                     if counts[1] else None)
            finished = done >= request.max_samples
            image = mean.astype(np.float32)
            denoised = False
            notes = img.notes
            if finished and request.denoise:
                from radiance_probes.rendering.denoise.filter import shared_denoiser
                result = shared_denoiser()(image)
                if result.denoised:
                    image, denoised = result.image.astype(np.float32), True
                elif result.note:
                    notes = (*notes, result.note)
            self._deliver(Frame(image, request.serial, "done" if finished else "refining",
                                request.method, done, request.max_samples, error, denoised,
                                1e3 * (time.perf_counter() - start), notes))
            if self._superseded(request):
                return
            if not math.isfinite(float(mean.max())):
                raise RuntimeError("the image holds non-finite values")


def _worker_main(conn, gl_backend) -> None:
    """The worker process: requests and arrays in through `conn`, frames and errors out."""
    send_lock = threading.Lock()

    def send(message) -> None:
        with send_lock:
            try:
                conn.send(message)
            except (BrokenPipeError, OSError):
                pass

    server = _Server(lambda frame: send(("frame", frame)), lambda text: send(("error", text)),
                     gl_backend)
    arrays: dict[int, np.ndarray] = {}
    try:
        while True:
            try:
                kind, *payload = conn.recv()
            except (EOFError, OSError):
                break
            if kind == "data":
                token, array = payload
                arrays.clear()            # one scene at a time
                arrays[token] = array
            elif kind == "request":
                (request,) = payload
                request.data = arrays.get(request.data_token)
                if request.data is None:
                    send(("error", "the plugin's renderer lost the volume: press Render again"))
                    continue
                server.submit_as(request)
            elif kind == "close":
                break
    finally:
        server.close()
        send(("closed",))


def worker_entry(address: str, gl_backend: str | None) -> None:
    """The worker process's entry (RenderEngine starts it): connects back, then serves."""
    import os
    from multiprocessing.connection import Client
    conn = Client(address, "AF_UNIX",
                  authkey=bytes.fromhex(os.environ.pop("RADIANCE_PROBES_NAPARI_KEY")))
    _worker_main(conn, gl_backend)


class RenderEngine:
    """``engine = RenderEngine(deliver, on_error)``; ``engine.submit(request)``; ``engine.close()``.
    The renderer runs in a worker process (module docstring); `deliver(Frame)` and
    `on_error(str)` are called on this process's reader thread."""

    def __init__(self, deliver, on_error, gl_backend: str | None = None):
        import os
        import secrets
        import subprocess
        import sys
        import tempfile
        from multiprocessing.connection import Listener
        # a plain `python -c` child talking over a local socket: multiprocessing's spawn would run
        # the caller's main script again in the child (a napari script with no main guard)
        folder = tempfile.mkdtemp(prefix="radiance-probes-napari-")
        address = os.path.join(folder, "socket")
        authkey = secrets.token_bytes(16)
        listener = Listener(address, "AF_UNIX", authkey=authkey)
        env = {**os.environ, "RADIANCE_PROBES_NAPARI_KEY": authkey.hex()}
        # Mesa's llvmpipe (no GPU) renders on every core unless told: one is left to napari's
        # own drawing and event loop (a GPU driver ignores the variable)
        env.setdefault("LP_NUM_THREADS", str(max(1, (os.cpu_count() or 2) - 1)))
        code = ("from radiance_probes.napari_plugin.engine import worker_entry; "
                f"worker_entry({address!r}, {gl_backend!r})")
        self._process = subprocess.Popen([sys.executable, "-c", code], env=env,
                                         stdin=subprocess.DEVNULL)
        try:
            listener._listener._socket.settimeout(WORKER_START_SECONDS)
            self._conn = listener.accept()
        except OSError as exc:
            self._process.kill()
            raise RuntimeError(f"the plugin's renderer process did not start ({exc})") from None
        finally:
            listener.close()
        self._deliver, self._on_error = deliver, on_error
        self._serial = 0
        self._token = 0
        self._sent = None             # the array last sent
        self._busy_serial = 0         # the latest request not yet answered with a final frame
        self._lock = threading.Lock()
        self.frames = 0
        self._reader = threading.Thread(target=self._read, name="radiance-probes-napari-reader",
                                        daemon=True)
        self._reader.start()

    @property
    def latest(self) -> int:
        return self._serial

    def busy(self) -> bool:
        """A request is being served (no final frame or error for the latest yet)."""
        return self._busy_serial != 0

    def submit(self, request: Request) -> int:
        with self._lock:
            if request.data is not self._sent:
                self._token += 1
                self._conn.send(("data", self._token, np.ascontiguousarray(request.data)))
                self._sent = request.data
            self._serial += 1
            message = Request(**{**request.__dict__, "data": None, "serial": self._serial,
                                 "data_token": self._token})
            self._busy_serial = self._serial
            self._conn.send(("request", message))
            request.serial = self._serial
            return self._serial

    def _read(self) -> None:
        while True:
            try:
                kind, *payload = self._conn.recv()
            except (EOFError, OSError):
                return
            if kind == "frame":
                frame = payload[0]
                self.frames += 1
                if frame.stage == "done" and frame.serial == self._serial:
                    self._busy_serial = 0
                self._deliver(frame)
            elif kind == "error":
                self._busy_serial = 0
                self._on_error(payload[0])
            elif kind == "closed":
                return

    def close(self, timeout: float = 20.0) -> None:
        if self._process is None:
            return
        try:
            self._conn.send(("close",))
        except (BrokenPipeError, OSError):
            pass
        try:
            self._process.wait(timeout)
        except Exception:
            self._process.kill()
            self._process.wait(5)
        self._reader.join(5)
        self._conn.close()
        self._process = None
