"""The denoising stage: Intel Open Image Denoise (OIDN) through `pyoidn`, over any noisy image.

The filter runs on OIDN's CUDA device where one is present (the NVIDIA GPU the renderer runs on),
and on its CPU device elsewhere (llvmpipe, CI). It uses OIDN's own devices and buffers, no deep
learning framework. An image goes in as linear HDR RGB (SPEC.md's image), optionally with noise-free
guides of the same size (glsl/denoise_guide_images.comp: the expected albedo and normal along each camera
ray), and comes out as a finite, non-negative image of the same shape.

It never takes an image away: where the library cannot load, the device cannot be made, or the
filter fails, `denoise` returns the raw image with a note saying why (`Denoised.note`), and the
stage remembers the failure so that a viewer does not try again every frame.

Cost (`Denoised.ms`, wall time; OIDN's execute is synchronous): prepare_ms (the colour's copy into
the filter's memory where the caller did not read GL straight into it, a pass that finds
non-finite values, and a new guide's upload), filter_ms, check_ms (a pass over the output and its
copy where asked), means_ms (the raw image's tile means and their restoring, keep_block_means).
The read-back from GL and the upload of the result are the caller's, and records add them.

keep_block_means is the host path and the NumPy twin of the GL one (kept_means.py: two compute
passes, glsl/tile_means.comp and glsl/keep_tile_means.comp), which Renderer.denoise (from the
accumulation), the viewer and the bench take: they call the filter with keep_means and
check_output off, and restore the means and check the output on the GPU after the upload.
Callers that hold host arrays (auto_progressive.py, an image given to Renderer.denoise) keep
the host path.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

import numpy as np

QUALITIES = ("high", "balanced", "fast")
# What guides the filter (Renderer.denoise_guides): nothing but the colour; the expected albedo
# where each camera ray first scatters; that albedo and the normal there; the raymarched image
# over the probes, scaled into [0, 1], in the albedo's place.
GUIDE_SETS = ("none", "albedo", "albedo-normal", "probes")
# "auto" (choose_guides): what bench/h200-denoise measured best, on the geometric mean of seven
# scenes' errors: the probes' image wherever the method has probes, up to PROBE_GUIDE_MAX_SPP (25-30%
# below the colour alone at 1-4 samples, 10% at 64, even at 256, 13% above at 1024); for the path
# tracer the albedo and normal up to NORMAL_GUIDE_MAX_SPP (14-16% below at 1-4, 8% at 16, 3% above
# at 64); else the colour alone.
GUIDE_CHOICES = ("auto", *GUIDE_SETS)
PROBE_GUIDE_MAX_SPP = 256
NORMAL_GUIDE_MAX_SPP = 16


def choose_guides(guides: str, spp: int, has_probes: bool) -> str:
    """The guide set to use: `guides` itself, or for "auto" the measured best for an image of
    `spp` samples (has_probes: the method's probes are in hand, so their image costs a raymarch)."""
    if guides not in GUIDE_CHOICES:
        raise ValueError(f"unknown denoise guides {guides!r} (known: {', '.join(GUIDE_CHOICES)})")
    if guides != "auto":
        return guides
    if has_probes and spp <= PROBE_GUIDE_MAX_SPP:
        return "probes"
    return "albedo-normal" if spp <= NORMAL_GUIDE_MAX_SPP else "none"


# radiance_as_albedo: the image's value at this quantile (of each pixel's largest channel) maps to 1
ALBEDO_SCALE_QUANTILE = 0.995
DEVICES = ("auto", "cuda", "cpu")
INSTALL_HINT = "pip install pyoidn"


@dataclass
class Denoised:
    """One call's result: the image (the raw one where `note` says the filter did not run; None
    where kept_means.denoise_on_gl left it in a texture), what the filter ran on ("cuda", "cpu"
    or None), wall ms of its parts (they add up to the whole), and `signed`: the image may dip
    below zero (it was filtered as its positive and negative parts). `means_parts_ms`: where
    means_ms was GL passes, its parts (not counted again in total_ms)."""
    image: np.ndarray | None
    device: str | None
    note: str | None = None
    ms: dict = field(default_factory=dict)
    signed: bool = False
    means_parts_ms: dict = field(default_factory=dict)

    @property
    def denoised(self) -> bool:
        return self.device is not None

    @property
    def total_ms(self) -> float:
        return float(sum(self.ms.values()))


def sanitize(image: np.ndarray) -> np.ndarray:
    """A float32 (H, W, 3) copy with NaN, negative and infinite values made 0 (an infinite value
    is no radiance the filter can use, and one would spread over its neighbours)."""
    out = np.array(image, dtype=np.float32, copy=True)
    out[~np.isfinite(out)] = 0.0
    np.maximum(out, 0.0, out=out)
    return out


def _all_finite(image: np.ndarray) -> bool:
    """Whether an (H, W, 3 or 4) image holds no NaN or infinity: one float32 sum over the whole
    buffer (fast), and only where that overflows or is NaN a pixel-wise look at the colour."""
    if np.isfinite(image.sum(dtype=np.float32)):
        return True
    return bool(np.isfinite(image[..., :3]).all())


def _make_usable(image: np.ndarray) -> None:
    """In place: NaN and infinite values to 0 (only where there are any: one summing pass finds
    out), negatives to 0."""
    if not np.isfinite(image.sum(dtype=np.float64)):
        np.nan_to_num(image, copy=False, nan=0.0, posinf=0.0, neginf=0.0)
    np.maximum(image, 0.0, out=image)


# keep_block_means: the side of the blocks whose means the filtered image is given back
KEEP_MEANS_BLOCK = 32


def _block_means(image: np.ndarray, block: int) -> np.ndarray:
    """Means over block x block tiles (H/b, W/b rounded up, C); partial tiles at the right and
    bottom edges average the pixels they have. Summed along x, then y (float32 partial sums of
    at most `block` values, then float64)."""
    h, w, c = image.shape
    hb, wb = -(-h // block), -(-w // block)
    rows = np.add.reduceat(image, np.arange(0, w, block), axis=1)          # (h, wb, c)
    sums = np.add.reduceat(rows.astype(np.float64), np.arange(0, h, block), axis=0)
    ys = np.minimum(block, h - np.arange(hb) * block)
    xs = np.minimum(block, w - np.arange(wb) * block)
    return sums / (ys[:, None, None] * xs[None, :, None])


# The correction's field is interpolated at cells of this many pixels and held constant within a
# cell (a smooth field of a tile's scale: steps of a fraction of a percent over 8 pixels)
KEEP_MEANS_CELL = 8


def _cell_field(field: np.ndarray, h: int, w: int, block: int, cell: int) -> np.ndarray:
    """`field` (tiles, C) interpolated linearly between tile centres at the centres of
    cell x cell pixel cells: (ceil(h / cell), ceil(w / cell), C)."""
    hb, wb = field.shape[:2]

    def weights(n_cells, blocks):
        centre = ((np.arange(n_cells) + 0.5) * cell) / block - 0.5
        lo = np.clip(np.floor(centre).astype(np.int64), 0, blocks - 1)
        hi = np.minimum(lo + 1, blocks - 1)
        return lo, hi, np.clip(centre - lo, 0.0, 1.0)
    x0, x1, fx = weights(-(-w // cell), wb)
    y0, y1, fy = weights(-(-h // cell), hb)
    rows = field[:, x0] * (1.0 - fx)[None, :, None] + field[:, x1] * fx[None, :, None]
    return (rows[y0] * (1.0 - fy)[:, None, None] + rows[y1] * fy[:, None, None]).astype(np.float32)


def _apply_cells(image: np.ndarray, scale: np.ndarray | None, add: np.ndarray, cell: int) -> None:
    """In place: image = image * scale + add, each (cells, C) held constant within its cell."""
    h, w, c = image.shape
    hc, wc = h // cell, w // cell
    if wc * cell == w and image.flags.c_contiguous:
        # the cells' values repeated along each row first: the products then run over whole rows
        # (3x faster than broadcasting into cell x cell x C blocks, the same products)
        body = image[:hc * cell].reshape(hc, cell, w, c)
        if scale is not None:
            body *= np.repeat(scale[:hc, :wc], cell, axis=1)[:, None]
        body += np.repeat(add[:hc, :wc], cell, axis=1)[:, None]
    else:
        body = image[:hc * cell, :wc * cell].reshape(hc, cell, wc, cell, c)
        if scale is not None:
            body *= scale[:hc, None, :wc, None]
        body += add[:hc, None, :wc, None]
    for rows, cols, ry, rx in ((slice(0, hc * cell), slice(wc * cell, w), slice(0, hc), wc),
                               (slice(hc * cell, h), slice(0, w), hc, slice(None))):
        strip = image[rows, cols]
        if strip.size == 0:
            continue
        # the strips past the last whole cell: each pixel its cell's values
        ys = np.arange(strip.shape[0]) // cell + (0 if isinstance(ry, slice) else ry)
        xs = (np.arange(strip.shape[1]) + cols.start) // cell
        if scale is not None:
            strip *= scale[ys][:, xs]
        strip += add[ys][:, xs]


def keep_block_means(raw_means: np.ndarray, filtered: np.ndarray, block: int = KEEP_MEANS_BLOCK,
                     signed: bool = False) -> None:
    """In place: gives `filtered` back the raw image's block means (`raw_means`, _block_means of
    the raw image), the correction interpolated linearly between tile centres (smooth: a tile's
    mean has block^2 times a pixel's samples, so it adds little noise). Where a tile lost energy
    the difference is added; where it gained, it is scaled down by the means' ratio, so that a
    non-negative image stays non-negative (`signed`: the difference throughout).

    Why: OIDN is not mean-preserving on heavy-tailed noise. On the stress battery a filtered
    image's mean moved by up to 4.5% at 4 samples (a lone bright sample counted as noise and
    taken away) and, for signed images clamped at 0, by 12% (bench/h200-denoise/battery). The raw
    image is unbiased: the energy it holds at the scale of a tile is the estimate to keep."""
    h, w, c = filtered.shape
    own = _block_means(filtered, block)
    diff = raw_means - own
    cell = KEEP_MEANS_CELL
    if signed:
        _apply_cells(filtered, None, _cell_field(diff, h, w, block, cell), cell)
        return
    gained = diff < 0
    scale = np.where(gained, raw_means / np.where(own > 0, own, 1.0), 1.0)
    add = np.where(gained, 0.0, diff)
    _apply_cells(filtered, _cell_field(scale, h, w, block, cell),
                 _cell_field(add, h, w, block, cell), cell)


def radiance_as_albedo(image: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """A noise-free radiance image (the raymarched probes) as an albedo guide: divided by one
    scale, the ALBEDO_SCALE_QUANTILE quantile of each pixel's largest channel, and clipped to
    [0, 1] (OIDN's range for an albedo). One scale keeps the ratios between pixels, which is
    what the filter reads from a guide; the brightest half percent clip. NaN, infinite and
    negative values count as 0. `out`: an (H, W, 3) float32 array to write it into (the
    filter's own guide memory, Denoiser.guide_staging): then the only new array is the largest
    channel's (the quantile partitions it in place)."""
    image = np.asarray(image)[..., :3]
    if out is None:
        out = np.empty(image.shape, np.float32)
    elif out.shape != image.shape or out.dtype != np.float32:
        raise ValueError(f"radiance_as_albedo: out is {out.shape} {out.dtype}, the image "
                         f"{image.shape}")
    # the largest channel by two maximums, and the scaling in place: max over a last axis of 3
    # and a new array for image / scale took 0.14 s of 0.18 at 1080p (a hitch whenever the
    # viewer's probes change); the quantile partitions that array in place (it is ours)
    source = image
    peak = np.maximum(np.maximum(image[..., 0], image[..., 1]), image[..., 2])
    if image.dtype != np.float32 or not np.isfinite(peak.sum(dtype=np.float64)):
        # a NaN or +inf (the peak holds every one: a -inf channel is below the others, and
        # comes out 0 either way): the image made usable first, as sanitize makes it
        np.copyto(out, image, casting="same_kind")
        out[~np.isfinite(out)] = 0.0
        np.maximum(out, 0.0, out=out)
        source = out
        peak = np.maximum(np.maximum(out[..., 0], out[..., 1]), out[..., 2])
    np.maximum(peak, 0.0, out=peak)
    scale = (float(np.quantile(peak, ALBEDO_SCALE_QUANTILE, overwrite_input=True))
             if peak.size else 0.0)
    if not scale > 0.0:
        out[...] = 0.0
        return out
    # negative values divide to below 0 and clip to 0: what their making usable gives
    np.divide(source, scale, out=out)
    return np.clip(out, 0.0, 1.0, out=out)


def _check_image(name: str, image: np.ndarray, shape: tuple | None = None) -> None:
    if image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) == 0:
        raise ValueError(f"denoise: the {name} image must be (height, width, 3), got {image.shape}")
    if shape is not None and image.shape != shape:
        raise ValueError(f"denoise: the {name} image is {image.shape}, the colour {shape}")


class Denoiser:
    """OIDN's RT filter on one device, made on first use and kept (its weights load once).

    `device`: "auto" (CUDA where OIDN finds a CUDA GPU, else the CPU), "cuda" or "cpu".
    `quality`: OIDN's "high", "balanced" or "fast"."""

    def __init__(self, device: str = "auto", quality: str = "high"):
        if device not in DEVICES:
            raise ValueError(f"denoise device must be one of {DEVICES}, got {device!r}")
        if quality not in QUALITIES:
            raise ValueError(f"denoise quality must be one of {QUALITIES}, got {quality!r}")
        self.requested = device
        self.quality = quality
        self.device: str | None = None     # what it runs on once made
        self.failure: str | None = None    # why it cannot run (then every call returns the raw image)
        self._oidn = None
        self._device = None
        self._filters: dict = {}           # (width, height, guides) -> (filter, buffers)
        # one caller at a time: the viewer filters on a thread of its own (filter_worker.py)
        self.lock = threading.RLock()

    # ---- the library and its device ------------------------------------------------------------
    def _load(self) -> bool:
        if self._device is not None:
            return True
        if self.failure is not None:
            return False
        try:
            pyoidn = _import_pyoidn()
        except Exception as exc:   # ImportError, or its native library failing to load
            self.failure = (f"the denoiser is not available ({type(exc).__name__}: {exc}); "
                            f"{INSTALL_HINT} to use it. Showing the image as rendered.")
            return False
        try:
            kind = self._pick(pyoidn)
            device = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CUDA if kind == "cuda"
                                   else pyoidn.OIDN_DEVICE_TYPE_CPU)
            device.commit()
            error = device.get_error()
            if error:
                device.release()
                raise RuntimeError(error)
        except Exception as exc:
            self.failure = (f"the denoiser could not start its {self.requested} device "
                            f"({exc}). Showing the image as rendered.")
            return False
        self._oidn, self._device, self.device = pyoidn, device, kind
        return True

    def _pick(self, pyoidn) -> str:
        if self.requested == "cpu":
            return "cpu"
        cuda = False
        try:
            cuda = bool(pyoidn.Device.is_cuda_available(0))
        except Exception:
            cuda = False
        if self.requested == "cuda" and not cuda:
            raise RuntimeError("OIDN finds no CUDA GPU")
        return "cuda" if cuda else "cpu"

    @property
    def available(self) -> bool:
        """Whether the filter can run (loads the library and its device on first use)."""
        return self._load()

    # ---- the filter ----------------------------------------------------------------------------
    # The colour and the output live in pinned host memory that OIDN's device reads and writes
    # directly (OIDN_STORAGE_HOST): the caller reads GL straight into the colour (staging()), and
    # the result is read where the filter wrote it. The guides live there too: a different array
    # is copied in (clipped to its range) once, and a caller that makes a new guide for every
    # image (refine's probes guide, from each raymarched image) writes it in place
    # (guide_staging). Measured on an H200 (lab/denoise_io.py, docs/experiments.md): a copy
    # through pageable memory there moved about 1 GB/s, and was most of a 512^2 frame's 12 ms
    # around a 1.1 ms filter; a 1080p guide's upload from pageable memory was most of the 60-80 ms
    # a refine filter job's `prepare` took beyond its colour's copy
    # (bench/h200-interact-refine-56/filter-job).
    def _filter_for(self, width: int, height: int, guides: tuple[str, ...]):
        key = (width, height, guides)
        if key in self._filters:
            return self._filters[key]
        for old_key in [k for k in self._filters if k[:2] != (width, height)]:
            self._release_filter(self._filters.pop(old_key))   # one size at a time (a resize)
        host = self._oidn.OIDN_STORAGE_HOST if self.device == "cuda" else None
        guide_buffers = {name: self._buffer(width * height * 12, host) for name in guides}
        entry = self._make_filter(width, height, guides, guide_buffers)
        entry["buffers"].update(guide_buffers)    # released with the entry
        views = {name: self._view(b).reshape(height, width, 3) for name, b in guide_buffers.items()}
        entry.update(guide_views=views, guides={}, negative=None)
        self._filters[key] = entry
        return entry

    def _make_filter(self, width: int, height: int, guides: tuple[str, ...],
                     guide_buffers: dict) -> dict:
        """An RT filter with a colour and an output buffer of its own (on CUDA in pinned host
        memory) reading `guide_buffers`: {"filter", "buffers" (its own), "color" (H, W, 4 view),
        "output" (H, W, 3 view)}."""
        oidn = self._oidn
        flt = oidn.Filter(self._device, oidn.OIDN_FILTER_TYPE_RT)
        pixels = width * height
        host = oidn.OIDN_STORAGE_HOST if self.device == "cuda" else None
        own = {"color": self._buffer(pixels * 16, host), "output": self._buffer(pixels * 12, host)}
        flt.set_image("color", own["color"], oidn.OIDN_FORMAT_FLOAT3, width, height, 0, 16,
                      width * 16)
        flt.set_image("output", own["output"], oidn.OIDN_FORMAT_FLOAT3, width, height)
        for name in guides:
            flt.set_image(name, guide_buffers[name], oidn.OIDN_FORMAT_FLOAT3, width, height)
        flt.set_bool("hdr", True)
        flt.set_bool("cleanAux", True)    # the guides are noise-free (no prefiltering)
        flt.set_quality({"high": oidn.OIDN_QUALITY_HIGH, "balanced": oidn.OIDN_QUALITY_BALANCED,
                         "fast": oidn.OIDN_QUALITY_FAST}[self.quality])
        flt.commit()
        self._raise_error("filter setup")
        return {"filter": flt, "buffers": own,
                "color": self._view(own["color"]).reshape(height, width, 4),
                "output": self._view(own["output"]).reshape(height, width, 3)}

    def _negative_for(self, entry, width: int, height: int, guides: tuple[str, ...]):
        """A signed image's negative part's filter, beside `entry`'s: a colour and an output
        buffer of its own and the same guides, so that the part is written straight into its
        colour (one pass) and both outputs are read once, into their difference. Made at the
        first signed image of the size (or warm's `signed`): a second filter's device memory."""
        if entry["negative"] is None:
            entry["negative"] = self._make_filter(
                width, height, guides, {n: entry["buffers"][n] for n in guides})
        return entry["negative"]

    def _buffer(self, nbytes: int, storage):
        return (self._oidn.Buffer(self._device, nbytes) if storage is None else
                self._oidn.Buffer(self._device, nbytes, storage=storage))

    def _view(self, buffer) -> np.ndarray:
        """A NumPy view of a buffer the host can address (host storage; the CPU device's)."""
        from pyoidn.capi import oidn_ffi
        return np.frombuffer(oidn_ffi.buffer(buffer.get_data(), buffer.size), np.float32)

    def _raise_error(self, what: str) -> None:
        error = self._device.get_error()
        if error:
            raise RuntimeError(f"OIDN {what}: {error}")

    @staticmethod
    def _release_filter(entry) -> None:
        if entry.get("negative") is not None:
            Denoiser._release_filter(entry["negative"])
        entry["filter"].release()
        for b in entry["buffers"].values():
            b.release()

    def staging(self, width: int, height: int, guides: tuple[str, ...] = ()) -> np.ndarray | None:
        with self.lock:
            return self._staging(width, height, guides)

    def _staging(self, width: int, height: int, guides: tuple[str, ...] = ()) -> np.ndarray | None:
        """The colour's RGBA float32 (height, width, 4) in the filter's own memory, for a caller
        that reads GL straight into it (texture.read_into) and then passes it as `color`: no copy.
        None where the filter cannot run."""
        if not self._load():
            return None
        try:
            return self._filter_for(width, height, tuple(guides))["color"]
        except Exception as exc:
            self.failure = f"the denoiser failed ({exc}). Showing the image as rendered."
            self.close()
            return None

    def guide_staging(self, width: int, height: int, guides: tuple[str, ...],
                      name: str) -> np.ndarray | None:
        with self.lock:
            return self._guide_staging(width, height, guides, name)

    def _guide_staging(self, width: int, height: int, guides: tuple[str, ...],
                       name: str) -> np.ndarray | None:
        """Guide `name`'s (height, width, 3) float32 in the filter's own memory (the filter for
        this size and `guides`), for a caller that writes a new guide for each image into it and
        passes it as that guide: no copy. It is taken as written: the caller makes it finite and
        in the guide's range (the filter's thread copies the probes guide made on the GPU into
        it, probe_guide.py). None where the filter cannot run."""
        if name not in guides:
            raise ValueError(f"guide_staging: {name!r} is not one of the guides {guides}")
        if not self._load():
            return None
        try:
            return self._filter_for(width, height, tuple(guides))["guide_views"][name]
        except Exception as exc:
            self.failure = f"the denoiser failed ({exc}). Showing the image as rendered."
            self.close()
            return None

    def warm(self, width: int, height: int, guides: tuple[str, ...] = (),
             signed: bool = False) -> float:
        with self.lock:
            return self._warm(width, height, guides, signed)

    def _warm(self, width: int, height: int, guides: tuple[str, ...] = (),
              signed: bool = False) -> float:
        """Makes the filter for this size and guides and runs it once on a black image, so that
        the next call costs what every later one does (the weights' load and the device's first
        run, about 0.1 s on an H200, happen here); with `signed` the negative part's filter as
        well. Wall ms taken; 0 where the filter cannot run (its note is in `failure`)."""
        if not self._load():
            return 0.0
        t0 = time.perf_counter()
        try:
            entry = self._filter_for(width, height, tuple(guides))
            entry["color"][...] = 0.0
            for name in guides:   # black guides until a caller gives its own (then copied in)
                entry["guide_views"][name][...] = 0.0
                entry["guides"].pop(name, None)
            self._execute(entry)
            if signed:
                negative = self._negative_for(entry, width, height, tuple(guides))
                negative["color"][...] = 0.0
                self._execute(negative)
        except Exception as exc:
            self.failure = f"the denoiser failed ({exc}). Showing the image as rendered."
            self.close()
            return 0.0
        return 1e3 * (time.perf_counter() - t0)

    def __call__(self, *args, **kwargs) -> "Denoised":
        with self.lock:
            return self._call(*args, **kwargs)

    def _call(self, color: np.ndarray, albedo: np.ndarray | None = None,
                 normal: np.ndarray | None = None, copy: bool = True,
                 signed: bool = False, keep_means: bool = True, check_output: bool = True,
                 color_finite: bool = False, raw_means: np.ndarray | None = None,
                 out: np.ndarray | None = None, has_negative: bool | None = None) -> Denoised:
        """The denoised colour (H, W, 3) of `color` (H, W, 3 or 4: RGB, or RGBA whose alpha is
        ignored), guided by the noise-free `albedo` (in [0, 1]) and `normal` (in [-1, 1]) where
        given (a normal needs an albedo: OIDN's rule). Negative, NaN and infinite colours are
        taken as 0, except with `signed`: an estimate whose pixels may be negative (`guided`'s
        level 1 is a signed residual) is filtered as its positive and its negative part, each
        non-negative, and the result is their difference (two filter runs). Clamping a signed
        image at 0 instead made the denoised image's mean 11-12% higher than the raw one's on the
        thin shells of the stress battery (bench/h200-denoise/battery). `copy` False: the image
        is a view of the filter's output, valid until the next call. `keep_means`: the result
        keeps the raw image's means over KEEP_MEANS_BLOCK-pixel tiles (keep_block_means: OIDN
        alone moved an image's mean by up to 4.5% on heavy-tailed noise). `check_output` False:
        no host pass makes the output finite and non-negative, and without `copy` or
        `keep_means` the image is the filter's output buffer itself (a caller that uploads it and
        restores the means on the GPU, kept_means.KeptMeans.restore, checks it there).
        `color_finite`: the caller has found the colour finite (KeptMeans.raw_means), so without
        `keep_means` no pass looks for non-finite values. `raw_means`: the colour's tile means
        (tiles down, across, 3 or more; _block_means' or glsl/tile_means.comp's) made by the
        caller, kept as keep_means keeps its own (where one is not finite, the colour is made
        usable and the means made again here). `out`: an (H, W, 3) float32 array of the
        caller's that the result is written into (one read of the filter's output buffer, for a
        signed image its two parts' difference), then returned as the image. `has_negative`:
        whether a signed colour holds a negative value, where the caller knows (the least value
        glsl/tile_means.comp gives each tile); None: a pass over the colour looks. Where the filter
        cannot run: the raw colour, made finite (and, unless signed, non-negative), with a
        note."""
        color = np.asarray(color)
        if color.ndim != 3 or color.shape[2] not in (3, 4) or min(color.shape[:2]) == 0:
            raise ValueError(f"denoise: the colour image must be (height, width, 3), got "
                             f"{color.shape}")
        if normal is not None and albedo is None:
            raise ValueError("denoise: a normal guide needs an albedo guide as well (OIDN)")
        height, width = color.shape[:2]
        for name, image in (("albedo", albedo), ("normal", normal)):
            if image is not None:
                _check_image(name, np.asarray(image), (height, width, 3))
        if raw_means is not None:
            raw_means = np.asarray(raw_means)
            tiles = (-(-height // KEEP_MEANS_BLOCK), -(-width // KEEP_MEANS_BLOCK))
            if raw_means.ndim != 3 or raw_means.shape[:2] != tiles or raw_means.shape[2] < 3:
                raise ValueError(f"denoise: raw_means must be (tiles down, across, 3 or 4) = "
                                 f"{tiles} for a {width}x{height} image, got {raw_means.shape}")
            raw_means = raw_means[..., :3]
        if out is not None and (out.shape != (height, width, 3) or out.dtype != np.float32
                                or not out.flags.c_contiguous):
            raise ValueError(f"denoise: out must be a C-contiguous ({height}, {width}, 3) float32 "
                             f"array, got {out.shape} {out.dtype}")
        if not self._load():
            return Denoised(sanitize(color[..., :3]), None, self.failure)
        guides = {n: g for n, g in (("albedo", albedo), ("normal", normal)) if g is not None}
        t0 = time.perf_counter()
        try:
            entry = self._filter_for(width, height, tuple(guides))
            staged = entry["color"]
            if not np.shares_memory(color, staged):
                if color.shape[2] == 4 and color.dtype == np.float32 and color.flags.c_contiguous:
                    # whole pixels, one contiguous copy (the filter reads RGB at a 16-byte
                    # stride, never alpha): 1.8 ms against 8.2 ms for RGB alone at 1080p on
                    # this project's CPU machine; a refine filter job's largest host pass
                    # (bench/h200-interact-refine-56/filter-job)
                    np.copyto(staged, color)
                else:
                    staged[..., :3] = color[..., :3]
            for name, guide in guides.items():
                view = entry["guide_views"][name]
                if np.shares_memory(guide, view):   # written in place (guide_staging)
                    entry["guides"][name] = guide
                elif entry["guides"].get(name) is not guide:   # a new guide: copied in once
                    low = -1.0 if name == "normal" else 0.0
                    np.clip(np.asarray(guide), low, 1.0, out=view)   # infinities to the range
                    if not np.isfinite(view.sum(dtype=np.float32)):
                        np.nan_to_num(view, copy=False, nan=0.0)
                    entry["guides"][name] = guide
            t_means = time.perf_counter()
            if raw_means is not None:   # the caller's (a GPU pass over the same image)
                keep_means = True
            elif keep_means:
                raw_means = _block_means(staged[..., :3], KEEP_MEANS_BLOCK)
            raw_means_ms = 1e3 * (time.perf_counter() - t_means) if keep_means else 0.0
            keep_ms = 0.0
            # a non-finite pixel makes its tile's mean non-finite, so the means (where kept) find
            # one without a pass of their own
            if not (np.isfinite(raw_means).all() if raw_means is not None
                    else color_finite or _all_finite(staged)):
                _make_usable(staged) if not signed else np.nan_to_num(
                    staged, copy=False, nan=0.0, posinf=0.0, neginf=0.0)
                if raw_means is not None:
                    raw_means = _block_means(staged[..., :3], KEEP_MEANS_BLOCK)
            negative = None
            if signed and (staged[..., :3].min() < 0.0 if has_negative is None
                           else has_negative):
                # the negative part written straight into its own filter's colour (OIDN takes
                # the negative values of each part as 0)
                negative = self._negative_for(entry, width, height, tuple(guides))
                np.negative(staged, out=negative["color"])
            t1 = time.perf_counter()
            self._execute(entry)
            if negative is not None:
                self._execute(negative)
            t2 = time.perf_counter()
            given, out = out, entry["output"]
            if given is not None:   # the caller's array: the one read of the output
                if negative is not None:
                    np.subtract(out, negative["output"], out=given)
                else:
                    np.copyto(given, out)
                out = given
            elif raw_means is not None or copy or negative is not None:
                # one read of the filter's output buffer (host memory the device writes: reading
                # it is slow, and keeping the means reads and writes it three times) into memory
                # of our own, for a signed image the two parts' difference; handed out where
                # `copy` asks, made anew next call
                scratch = entry.pop("scratch", None) if copy else entry.get("scratch")
                if scratch is None:
                    scratch = np.empty_like(out)
                    if not copy:
                        entry["scratch"] = scratch
                if negative is not None:
                    np.subtract(out, negative["output"], out=scratch)
                else:
                    np.copyto(scratch, out)
                out = scratch
            if check_output and not _all_finite(out):   # (never seen) a filter's overflow
                _make_usable(out)
            if raw_means is not None:
                t_keep = time.perf_counter()
                keep_block_means(raw_means, out, signed=negative is not None)
                keep_ms = 1e3 * (time.perf_counter() - t_keep)
            t3 = time.perf_counter()
        except Exception as exc:
            self.failure = f"the denoiser failed ({exc}). Showing the image as rendered."
            self.close()
            return Denoised(sanitize(color[..., :3]), None, self.failure)
        return Denoised(out, self.device, None,
                        {"prepare_ms": 1e3 * (t1 - t0) - raw_means_ms,
                         "filter_ms": 1e3 * (t2 - t1), "check_ms": 1e3 * (t3 - t2) - keep_ms,
                         "means_ms": raw_means_ms + keep_ms}, signed=negative is not None)

    def _execute(self, entry) -> None:
        entry["filter"].execute()
        self._raise_error("filter")

    def close(self) -> None:
        for entry in self._filters.values():
            try:
                self._release_filter(entry)
            except Exception:
                pass
        self._filters.clear()
        if self._device is not None:
            try:
                self._device.release()
            except Exception:
                pass
        self._device = None


_shared: dict = {}


def _import_pyoidn():
    """pyoidn, imported without PyTorch: its utils module imports torch wherever it is installed
    (for tensor interop this project never uses). That import takes seconds of the interpreter
    (on the H200 machine it ran on the filter's thread during a load's first frames, holding the
    GIL from the frames: lab/experiments/frame_host_profile.py) and much memory. Where torch is
    already imported, pyoidn sees it as it is."""
    import sys
    if "pyoidn" in sys.modules or "torch" in sys.modules:
        import pyoidn
        return pyoidn
    sys.modules["torch"] = None        # `import torch` raises ImportError meanwhile
    try:
        import pyoidn
    finally:
        if sys.modules.get("torch", False) is None:
            del sys.modules["torch"]
    return pyoidn


def shared_denoiser(device: str = "auto", quality: str = "high") -> Denoiser:
    """One Denoiser a process per (device, quality): its weights and buffers are kept between
    frames and renders."""
    key = (device, quality)
    if key not in _shared:
        _shared[key] = Denoiser(device, quality)
    return _shared[key]
