"""The denoiser's kept tile means on the GPU: glsl/tile_means.comp and glsl/keep_tile_means.comp,
the twins of denoise.py's _block_means and keep_block_means (the host path, which callers
without GL keep: auto_progressive.py).

A GL flow (denoise_on_gl; Renderer.denoise, the viewer's Denoise switch, the bench) reads the
accumulation straight into the filter's colour, and the raw image's tile means come from one pass
over the same texture (their small array read back: a non-finite mean is how the host learns of a
non-finite pixel, which it then sanitizes in the colour as Denoiser does, and makes the means on
the host instead). After the filter its output goes up into an RGB32F texture, and two passes
give it back the raw means: the filtered image's own tile means, then the correction applied into
an RGBA32F texture, finite and (unless signed) non-negative, which is the check of the filter's
output as well. So the host neither sums the images nor passes over the filter's output."""
from __future__ import annotations

import time

import moderngl
import numpy as np

from radiance_probes.gl.shaders import compute_program, set_uniforms
from radiance_probes.rendering.denoise.filter import (KEEP_MEANS_BLOCK, KEEP_MEANS_CELL, Denoised,
                                                      _block_means, _make_usable)

# The texture unit the passes read their image from (no other pass binds it: the others bind
# their own units before each dispatch, and these stay untouched).
KEPT_MEANS_UNIT = 18


def tile_grid(width: int, height: int) -> tuple[int, int]:
    """Tiles (across, down) of KEEP_MEANS_BLOCK pixels over an image, partial ones included."""
    return -(-width // KEEP_MEANS_BLOCK), -(-height // KEEP_MEANS_BLOCK)


class KeptMeans:
    """The two passes, the tile means' storage buffers (the raw image's, the filtered image's)
    and scratch textures of the image's size (the filter's output uploaded; a result for callers
    without a texture of their own)."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        defines = {"KEEP_MEANS_TILE": KEEP_MEANS_BLOCK, "KEEP_MEANS_CELL": KEEP_MEANS_CELL}
        self._means_pass = compute_program(ctx, "tile_means.comp", defines)
        self._keep_pass = compute_program(ctx, "keep_tile_means.comp", defines)
        self._raw: moderngl.Buffer | None = None
        self._own: moderngl.Buffer | None = None
        self._size: tuple[int, int] | None = None       # the image size the buffers hold tiles of
        self._raw_of: tuple[int, int] | None = None     # the size whose raw means the buffer holds
        self._pending: tuple[int, int] | None = None    # a raw means pass dispatched, not yet read
        self._filtered: moderngl.Texture | None = None
        self._result: moderngl.Texture | None = None

    # ---- storage -------------------------------------------------------------------------------
    def _buffers(self, width: int, height: int) -> None:
        if self._size == (width, height):
            return
        for b in (self._raw, self._own):
            if b is not None:
                b.release()
        tiles = tile_grid(width, height)
        self._raw = self.ctx.buffer(reserve=16 * tiles[0] * tiles[1])
        self._own = self.ctx.buffer(reserve=16 * tiles[0] * tiles[1])
        self._size, self._raw_of = (width, height), None

    def _scratch(self, kept, width: int, height: int, components: int) -> moderngl.Texture:
        if kept is not None and kept.size == (width, height):
            return kept
        if kept is not None:
            kept.release()
        texture = self.ctx.texture((width, height), components, dtype="f4")
        texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        return texture

    def filtered_texture(self, width: int, height: int) -> moderngl.Texture:
        """The RGB32F texture the filter's output is uploaded into (upload)."""
        self._filtered = self._scratch(self._filtered, width, height, 3)
        return self._filtered

    def result_texture(self, width: int, height: int) -> moderngl.Texture:
        """An RGBA32F texture for the corrected image, for callers without one of their own."""
        self._result = self._scratch(self._result, width, height, 4)
        return self._result

    def upload(self, image: np.ndarray) -> moderngl.Texture:
        """The filter's output (H, W, 3 float32, a view of its buffer) in filtered_texture."""
        height, width = image.shape[:2]
        texture = self.filtered_texture(width, height)
        texture.write(image)
        return texture

    # ---- the passes ----------------------------------------------------------------------------
    def _tile_means(self, texture: moderngl.Texture, out: moderngl.Buffer, usable_only: bool,
                    signed: bool) -> None:
        texture.use(KEPT_MEANS_UNIT)
        out.bind_to_storage_buffer(0)
        set_uniforms(self._means_pass, {"image": KEPT_MEANS_UNIT, "usable_only": int(usable_only),
                                        "signed_radiance": int(signed)})
        self._means_pass.run(*tile_grid(*texture.size))

    def dispatch_means_into(self, texture: moderngl.Texture, out: moderngl.Buffer) -> None:
        """The tile means of `texture` as read (a non-finite pixel makes its tile's mean
        non-finite) into `out` (a buffer of at least 16 bytes a tile: tiles down, across, vec4),
        for a caller that reads them back itself (the viewer's filter jobs: FilterJob.raw_means,
        read back beside the image through a fence)."""
        tiles = tile_grid(*texture.size)
        if out.size < 16 * tiles[0] * tiles[1]:
            raise ValueError(f"dispatch_means_into: {out.size} bytes for {tiles[0]}x{tiles[1]} "
                             "tiles of 16")
        self.ctx.memory_barrier(moderngl.TEXTURE_FETCH_BARRIER_BIT)
        self._tile_means(texture, out, usable_only=False, signed=False)
        self.ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT)

    def dispatch_raw_means(self, texture: moderngl.Texture, signed: bool) -> None:
        """Starts the raw image's tile means pass over `texture` (read them with read_raw_means).
        Dispatched before the colour's read-back, whose wait for the GL work covers this pass
        too, so that reading the means back waits for nothing (after it, a second wait on the
        GPU cost 0.2-0.3 ms a frame on the H200)."""
        width, height = texture.size
        self._buffers(width, height)
        # the passes that wrote the texture through image stores
        self.ctx.memory_barrier(moderngl.TEXTURE_FETCH_BARRIER_BIT)
        self._tile_means(texture, self._raw, usable_only=False, signed=signed)
        self.ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT)
        self._pending = (width, height)

    def read_raw_means(self, staged: np.ndarray, signed: bool) -> np.ndarray:
        """The means dispatch_raw_means made (tiles down, across, 3), kept in the raw means'
        buffer for restore. `staged` is the same image in the filter's colour (read from the
        texture): where a mean is not finite, a pixel is not, and as Denoiser does the host makes
        the colour usable in place (NaN and infinities 0, and unless `signed` negatives 0) and the
        means from it (_block_means), written into the buffer."""
        if self._pending is None:
            raise RuntimeError("read_raw_means: no raw means pass dispatched")
        width, height = self._pending
        self._pending = None
        tiles = tile_grid(width, height)
        means = np.frombuffer(self._raw.read(), np.float32).reshape(tiles[1], tiles[0], 4)[..., :3]
        self._raw_of = (width, height)
        if np.isfinite(means).all():
            return means
        if signed:
            np.nan_to_num(staged, copy=False, nan=0.0, posinf=0.0, neginf=0.0)
        else:
            _make_usable(staged)
        host = _block_means(staged[..., :3], KEEP_MEANS_BLOCK).astype(np.float32)
        rows = np.zeros((tiles[1], tiles[0], 4), np.float32)
        rows[..., :3] = host
        self._raw.write(rows.tobytes())
        return host

    def raw_means(self, texture: moderngl.Texture, staged: np.ndarray, signed: bool) -> np.ndarray:
        """dispatch_raw_means then read_raw_means: the raw image's tile means (tiles down, across,
        3), made from `texture` on the GPU and read back; `staged` is the same image in the
        filter's colour, made usable where a mean is not finite (read_raw_means)."""
        self.dispatch_raw_means(texture, signed)
        return self.read_raw_means(staged, signed)

    def restore(self, filtered: moderngl.Texture, out: moderngl.Texture, signed: bool) -> None:
        """`out` (RGBA32F, the same size) = `filtered` (the filter's output, RGB32F) given back
        the raw means of the last raw_means: its own tile means, then the correction (alpha 1).
        `signed`: the filtered image may dip below zero (Denoised.signed): the difference
        throughout and no clamp at 0."""
        width, height = filtered.size
        if self._raw_of != (width, height) or out.size != (width, height):
            raise ValueError(f"restore: a {width}x{height} image, raw means of {self._raw_of} "
                             f"and an output of {out.size}")
        self._tile_means(filtered, self._own, usable_only=True, signed=signed)
        self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
        self._raw.bind_to_storage_buffer(0)
        self._own.bind_to_storage_buffer(1)
        out.bind_to_image(0, read=False, write=True)
        set_uniforms(self._keep_pass, {"filtered": KEPT_MEANS_UNIT, "signed_radiance": int(signed)})
        self._keep_pass.run(-(-width // KEEP_MEANS_CELL), -(-height // KEEP_MEANS_CELL))
        # the display samples the result, a read-back reads it, a later pass may load it
        self.ctx.memory_barrier(moderngl.TEXTURE_FETCH_BARRIER_BIT
                                | moderngl.TEXTURE_UPDATE_BARRIER_BIT
                                | moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)

    def restore_given(self, filtered: moderngl.Texture, raw_means: np.ndarray,
                      out: moderngl.Texture, signed: bool) -> None:
        """restore with the raw means given (tiles down, across, 3: a filter job's,
        FilterResult.raw_means) instead of those of the last raw_means pass: written into the raw
        means' buffer first (130 KB at 1080p), so that any number of images under way each
        restore with their own."""
        width, height = filtered.size
        tiles = tile_grid(width, height)
        means = np.asarray(raw_means, np.float32)
        if means.shape[:2] != (tiles[1], tiles[0]) or means.ndim != 3 or means.shape[2] < 3:
            raise ValueError(f"restore_given: raw means of {means.shape} for a {width}x{height} "
                             f"image ({tiles[1]}, {tiles[0]}, 3)")
        self._buffers(width, height)
        rows = np.zeros((tiles[1], tiles[0], 4), np.float32)
        rows[..., :3] = means[..., :3]
        self._raw.write(rows)
        self._raw_of = (width, height)
        self.restore(filtered, out, signed)

    def release(self) -> None:
        for obj in (self._raw, self._own, self._filtered, self._result):
            if obj is not None:
                obj.release()
        self._raw = self._own = self._filtered = self._result = None
        self._size = self._raw_of = None
        self._means_pass.release()
        self._keep_pass.release()


def denoise_on_gl(kept: KeptMeans, denoiser, texture: moderngl.Texture, staged: np.ndarray,
                  albedo: np.ndarray | None, normal: np.ndarray | None, signed: bool,
                  result: moderngl.Texture, finish: bool = True,
                  read_result: bool = False) -> Denoised:
    """One denoised image of `texture` (an RGBA32F accumulation: rgb its mean) into `result`
    (RGBA32F of its size): the texture read into `staged` (denoiser.staging's colour), the raw
    tile means (kept.raw_means), the filter without its host means and output check, its output
    uploaded, kept.restore; with `finish`, a ctx.finish so that the wall times hold the GL work.

    Denoised.ms (wall ms, parts that add up to the whole): readback_ms (GL into the colour),
    prepare_ms, filter_ms, check_ms (the denoiser's: 0, the restore pass checks), means_ms (the
    GL passes: the raw means with their read-back, and the restore with the finish),
    upload_result_ms, and with `read_result` result_readback_ms (the corrected image read back
    as Denoised.image, H x W x 3; else image is None and the image is in `result`).
    Denoised.means_parts_ms splits means_ms into raw_means_ms and restore_ms. Where the filter
    cannot run, the denoiser's Denoised (the raw colour, made usable, with its note)."""
    ctx = kept.ctx
    ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)
    t0 = time.perf_counter()
    kept.dispatch_raw_means(texture, signed)
    ta = time.perf_counter()
    texture.read_into(staged)      # waits for the means pass as well
    t1 = time.perf_counter()
    kept.read_raw_means(staged, signed)
    t2 = time.perf_counter()
    d = denoiser(staged, albedo, normal, copy=False, signed=signed, keep_means=False,
                 check_output=False, color_finite=True)
    if not d.denoised:
        return d
    t3 = time.perf_counter()
    filtered = kept.upload(d.image)
    t4 = time.perf_counter()
    kept.restore(filtered, result, d.signed)
    if finish:
        ctx.finish()
    t5 = time.perf_counter()
    raw_ms, restore_ms = 1e3 * ((ta - t0) + (t2 - t1)), 1e3 * (t5 - t4)
    ms = {"readback_ms": 1e3 * (t1 - ta), "prepare_ms": d.ms["prepare_ms"],
          "filter_ms": d.ms["filter_ms"], "check_ms": d.ms["check_ms"],
          "means_ms": raw_ms + restore_ms, "upload_result_ms": 1e3 * (t4 - t3)}
    image = None
    if read_result:
        t6 = time.perf_counter()
        width, height = result.size
        image = np.frombuffer(result.read(), np.float32).reshape(height, width, 4)[..., :3].copy()
        ms["result_readback_ms"] = 1e3 * (time.perf_counter() - t6)
    return Denoised(image, d.device, None, ms, signed=d.signed,
                    means_parts_ms={"raw_means_ms": raw_ms, "restore_ms": restore_ms})
