"""GL sync objects (glFenceSync) polled without waiting, and read-backs that finish on a later
frame: a texture or a buffer copied on the GPU into a buffer of its own (a pixel buffer object
for a texture: glGetTexImage into GL_PIXEL_PACK_BUFFER returns at once), a fence after the copy,
and the host's copy made only once the fence has signalled (glClientWaitSync with a timeout of 0
asks, it never waits). moderngl 5 has no fences, so they go through the GLVND dispatch library
(libOpenGL), as the timestamps do (app/gl/timer.py); where it lacks them a fence reads as
signalled, and the host's read then waits for the GL work as glGetBufferSubData does."""
from __future__ import annotations

import ctypes
import ctypes.util

import moderngl
import numpy as np

GL_SYNC_GPU_COMMANDS_COMPLETE = 0x9117
GL_SYNC_FLUSH_COMMANDS_BIT = 0x00000001
GL_ALREADY_SIGNALED = 0x911A
GL_CONDITION_SATISFIED = 0x911C
GL_WAIT_FAILED = 0x911D

_gl = None


def _lib():
    global _gl
    if _gl is None:
        for name in (ctypes.util.find_library("OpenGL"), "libOpenGL.so.0",
                     ctypes.util.find_library("GL"), "libGL.so.1"):
            if not name:
                continue
            try:
                lib = ctypes.CDLL(name)
                lib.glFenceSync  # noqa: B018 (raises AttributeError when missing)
            except (OSError, AttributeError):
                continue
            lib.glFenceSync.restype = ctypes.c_void_p
            lib.glFenceSync.argtypes = [ctypes.c_uint, ctypes.c_uint]
            lib.glClientWaitSync.restype = ctypes.c_uint
            lib.glClientWaitSync.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_uint64]
            lib.glDeleteSync.argtypes = [ctypes.c_void_p]
            _gl = lib
            break
        else:
            _gl = False
    return _gl or None


class GpuFence:
    """A fence after the GL commands issued so far; `signaled()` asks whether they are done
    (never waits: the first ask flushes the commands so that the fence can signal)."""

    def __init__(self):
        self._gl = _lib()
        self._sync = self._gl.glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0) if self._gl else None
        self._done = self._sync is None
        self._flushed = False

    def signaled(self) -> bool:
        if self._done:
            return True
        flags = 0 if self._flushed else GL_SYNC_FLUSH_COMMANDS_BIT
        self._flushed = True
        status = self._gl.glClientWaitSync(self._sync, flags, 0)
        if status == GL_WAIT_FAILED:
            raise RuntimeError("glClientWaitSync failed (no current GL context?)")
        if status in (GL_ALREADY_SIGNALED, GL_CONDITION_SATISFIED):
            self.release()
            self._done = True
        return self._done

    def release(self) -> None:
        if self._sync is not None:
            self._gl.glDeleteSync(self._sync)
            self._sync = None


class PendingRead:
    """One read-back under way: `source` (a moderngl Texture, read whole as float32 RGBA or its
    components, or a Buffer) copied on the GPU into `staging` (a Buffer of at least its size,
    reused between reads) and a fence after it. `ready()` polls; `read()` is the host copy (it
    waits where the fence has not signalled: callers ask ready() first). `fence` makes the fence
    (tests hand in one that stays unsignalled)."""

    def __init__(self, ctx: moderngl.Context, source, staging: moderngl.Buffer, fence=GpuFence):
        self.ctx = ctx
        self.staging = staging
        if isinstance(source, moderngl.Buffer):
            self.nbytes = source.size
            ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT
                               | moderngl.SHADER_STORAGE_BARRIER_BIT)
            ctx.copy_buffer(staging, source, self.nbytes)
            self.shape = (self.nbytes // 4,)
        else:
            width, height = source.size
            self.nbytes = width * height * source.components * 4
            self.shape = (height, width, source.components)
            ctx.memory_barrier(moderngl.PIXEL_BUFFER_BARRIER_BIT
                               | moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT
                               | moderngl.TEXTURE_UPDATE_BARRIER_BIT)
            source.read_into(staging, alignment=4)
        self.fence = fence()
        self.polls = 0
        self.copied = 0          # bytes of the host copy made so far (read_some)
        self.out: np.ndarray | None = None

    def ready(self) -> bool:
        self.polls += 1
        return self.fence.signaled()

    def read(self, out: np.ndarray | None = None) -> np.ndarray:
        """The values as float32 of `shape` (into `out`, of that shape, where given)."""
        if out is None:
            out = np.empty(self.shape, np.float32)
        self.staging.read_into(out, size=self.nbytes)
        self.fence.release()
        return out

    def read_some(self, budget: "TransferBudget") -> bool:
        """The host copy in parts: as many bytes as `budget` has left this frame (into `out`,
        made on the first call where the caller did not set it: a float32 array of `shape`,
        HostArrays.next); True once the whole copy is made. The fence must have signalled
        (ready())."""
        if self.out is None:
            self.out = np.empty(self.shape, np.float32)
        elif self.out.shape != self.shape or self.out.dtype != np.float32:
            raise ValueError(f"read_some: out is {self.out.shape} {self.out.dtype}, the read-back "
                             f"{self.shape} float32")
        want = budget.take(self.nbytes - self.copied)
        if want:
            self.staging.read_into(self.out, size=want, offset=self.copied,
                                   write_offset=self.copied)
            self.copied += want
        if self.copied >= self.nbytes:
            self.fence.release()
            return True
        return False

    def release(self) -> None:
        self.fence.release()


class HostArrays:
    """The host arrays read-backs copy into (PendingRead.out), kept and handed out in turn,
    `count` a key: a 1080p RGBA32F image made anew for every read-back is 33 MB of fresh pages,
    each first written on the frame that copies into it, and dropped again later. Reused, the
    host copies write memory that is already mapped. An array handed out is written again only
    `count` read-backs of its key later: a caller holds at most count - 1 of its key's arrays
    (the viewer's filter jobs: one image under way a key, the one before it at most still read
    by a job that was dropped)."""

    def __init__(self, count: int = 2):
        if count < 1:
            raise ValueError(f"HostArrays: count must be at least 1, got {count}")
        self.count = count
        self._kept: dict = {}        # key -> (arrays, the next one's index)

    def next(self, key, shape: tuple) -> np.ndarray:
        """The next float32 array of `shape` for `key` (new ones until `count` are kept; all
        made anew where the shape changed)."""
        arrays, turn = self._kept.get(key, ([], 0))
        if arrays and arrays[0].shape != tuple(shape):
            arrays, turn = [], 0
        if len(arrays) < self.count:
            arrays.append(np.empty(shape, np.float32))
            out = arrays[-1]
        else:
            out = arrays[turn % self.count]
        self._kept[key] = (arrays, turn + 1)
        return out

    def clear(self) -> None:
        self._kept.clear()


class TransferBudget:
    """Bytes a frame may copy between host and GL (read-backs' host copies, uploads): a 1080p
    RGBA32F image is 33 MB, several ms of one frame each way, so a transfer is spread over
    frames at `per_frame` bytes a frame (at least one row's worth goes each frame)."""

    def __init__(self, per_frame: int):
        self.per_frame = per_frame
        self.left = per_frame

    def begin_frame(self) -> None:
        self.left = self.per_frame

    def take(self, want: int, unit: int = 4096) -> int:
        """Up to `want` bytes of what is left (whole `unit`s, at least one where any is asked
        and the budget is spent: every transfer moves)."""
        got = min(want, max(self.left, 0))
        if got < want:
            got -= got % unit
            if got <= 0:
                got = min(want, unit)
        self.left -= got
        return got


class ChunkedUpload:
    """An image (H, W, C float32) written into `texture` in bands of rows over frames, as
    `budget` allows (`step`: True once whole). Each band goes through a pixel buffer of its own
    (orphaned before each write: no wait for the last band's copy): the host copy into it is a
    memcpy, and the texture's copy from it runs on the GPU. Written straight from host memory
    (glTexSubImage2D from client memory) an 8 MB band took 3.5-6.5 ms of a frame's wall time on
    the H200 and up to 15 ms on the chest CT's frames (bench/h200-interact-refine-56: `upload`),
    against 1.5 ms for the read-backs' host copies of the same size."""

    def __init__(self, texture: moderngl.Texture, image: np.ndarray,
                 staging: moderngl.Buffer | None = None):
        """`staging`: a pixel buffer lent for the bands (kept by the caller, made once: a new
        one's first write costs the driver's allocation, 12 ms on the H200 for 16 MB); a band
        larger than it goes through one of the upload's own."""
        self.texture, self.image = texture, np.ascontiguousarray(image)
        self.rows = 0
        self._lent = staging
        self._staging: moderngl.Buffer | None = None

    def step(self, budget: TransferBudget) -> bool:
        height, width = self.image.shape[:2]
        row_bytes = self.image[0].nbytes
        want = budget.take((height - self.rows) * row_bytes, unit=row_bytes)
        n = want // row_bytes
        if n:
            band = self.image[self.rows:self.rows + n]
            staging = self._buffer_for(band.nbytes)
            staging.write(band)
            self.texture.write(staging, viewport=(0, self.rows, width, n))
            self.rows += n
        if self.rows >= height:
            self.release()
            return True
        return False

    def _buffer_for(self, nbytes: int) -> moderngl.Buffer:
        """The pixel buffer for a band of `nbytes`: the lent one where it holds it, else the
        upload's own; orphaned where it was written before."""
        if self._lent is not None and self._lent.size >= nbytes:
            self._lent.orphan()
            return self._lent
        if self._staging is None or self._staging.size < nbytes:
            if self._staging is not None:
                self._staging.release()
            self._staging = self.texture.ctx.buffer(reserve=nbytes)
        else:
            self._staging.orphan()
        return self._staging

    def release(self) -> None:
        if self._staging is not None:
            self._staging.release()
            self._staging = None


def start_read(ctx: moderngl.Context, source, buffers: dict, host: HostArrays,
               key) -> PendingRead:
    """A read-back of `source` (a Texture or a Buffer) through the staging buffer kept in
    `buffers` under `key` (made or grown as needed), into the next of `host`'s arrays for it."""
    nbytes = (source.size if isinstance(source, moderngl.Buffer)
              else source.size[0] * source.size[1] * source.components * 4)
    buf = buffers[key] = staging_buffer(ctx, buffers.get(key), nbytes)
    read = PendingRead(ctx, source, buf)
    read.out = host.next(key, read.shape)
    return read


def staging_buffer(ctx: moderngl.Context, kept: moderngl.Buffer | None,
                   nbytes: int) -> moderngl.Buffer:
    """`kept` where it holds `nbytes`, else a new buffer of that size (`kept` released)."""
    if kept is not None and kept.size >= nbytes:
        return kept
    if kept is not None:
        kept.release()
    return ctx.buffer(reserve=nbytes)
