"""The denoising stage: Intel Open Image Denoise (OIDN) through `pyoidn`, over any noisy image.

The filter runs on OIDN's CUDA device where one is present (the NVIDIA GPU the renderer runs on),
and on its CPU device elsewhere (llvmpipe, CI). It uses OIDN's own devices and buffers, no deep
learning framework. An image goes in as linear HDR RGB (SPEC.md's image), optionally with noise-free
guides of the same size (glsl/denoise_guides.comp: the expected albedo and normal along each camera
ray), and comes out as a finite, non-negative image of the same shape.

It never takes an image away: where the library cannot load, the device cannot be made, or the
filter fails, `denoise` returns the raw image with a note saying why (`Denoised.note`), and the
stage remembers the failure so that a viewer does not try again every frame.

Cost, measured by the caller's clock: the host copy to the filter's device, the filter, and the copy
back (`Denoised.ms`, wall time; OIDN's execute is synchronous). The read-back from GL and the upload
of the result are the caller's (the renderer's and the viewer's), and their records add them.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

QUALITIES = ("high", "balanced", "fast")
# What guides the filter (Renderer.denoise_guides): nothing but the colour; the expected albedo
# where each camera ray first scatters; that albedo and the normal there; the raymarched image
# over the probes, scaled into [0, 1], in the albedo's place.
GUIDE_SETS = ("none", "albedo", "albedo-normal", "probes")
# radiance_as_albedo: the image's value at this quantile (of each pixel's largest channel) maps to 1
ALBEDO_SCALE_QUANTILE = 0.995
DEVICES = ("auto", "cuda", "cpu")
INSTALL_HINT = "pip install pyoidn"


@dataclass
class Denoised:
    """One call's result: the image (the raw one where `note` says the filter did not run), what
    the filter ran on ("cuda", "cpu" or None), and wall ms of its parts."""
    image: np.ndarray
    device: str | None
    note: str | None = None
    ms: dict = field(default_factory=dict)

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


def radiance_as_albedo(image: np.ndarray) -> np.ndarray:
    """A noise-free radiance image (the raymarched probes) as an albedo guide: divided by one
    scale, the ALBEDO_SCALE_QUANTILE quantile of each pixel's largest channel, and clipped to
    [0, 1] (OIDN's range for an albedo). One scale keeps the ratios between pixels, which is
    what the filter reads from a guide; the brightest half percent clip."""
    image = sanitize(image)
    peak = image.max(axis=-1)
    scale = float(np.quantile(peak, ALBEDO_SCALE_QUANTILE)) if peak.size else 0.0
    if not scale > 0.0:
        return np.zeros_like(image)
    return np.clip(image / scale, 0.0, 1.0)


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

    # ---- the library and its device ------------------------------------------------------------
    def _load(self) -> bool:
        if self._device is not None:
            return True
        if self.failure is not None:
            return False
        try:
            import pyoidn
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
    def _filter_for(self, width: int, height: int, guides: tuple[str, ...]):
        key = (width, height, guides)
        if key in self._filters:
            return self._filters[key]
        for old in self._filters.values():   # one size at a time: the viewer's resize frees the last
            self._release_filter(old)
        self._filters.clear()
        oidn = self._oidn
        flt = oidn.Filter(self._device, oidn.OIDN_FILTER_TYPE_RT)
        nbytes = width * height * 3 * 4
        buffers = {}
        for name in ("color", "output", *guides):
            buffers[name] = oidn.Buffer(self._device, nbytes)
            flt.set_image(name, buffers[name], oidn.OIDN_FORMAT_FLOAT3, width, height)
        flt.set_bool("hdr", True)
        flt.set_bool("cleanAux", True)    # the guides are noise-free (no prefiltering)
        flt.set_quality({"high": oidn.OIDN_QUALITY_HIGH, "balanced": oidn.OIDN_QUALITY_BALANCED,
                         "fast": oidn.OIDN_QUALITY_FAST}[self.quality])
        flt.commit()
        self._raise_error("filter setup")
        self._filters[key] = (flt, buffers)
        return flt, buffers

    def _raise_error(self, what: str) -> None:
        error = self._device.get_error()
        if error:
            raise RuntimeError(f"OIDN {what}: {error}")

    @staticmethod
    def _release_filter(entry) -> None:
        flt, buffers = entry
        flt.release()
        for b in buffers.values():
            b.release()

    def __call__(self, color: np.ndarray, albedo: np.ndarray | None = None,
                 normal: np.ndarray | None = None) -> Denoised:
        """The denoised colour (H, W, 3), guided by the noise-free `albedo` (in [0, 1]) and
        `normal` (in [-1, 1]) where given (a normal needs an albedo: OIDN's rule). The raw
        colour, made finite and non-negative, with a note where the filter cannot run."""
        color = np.asarray(color)
        _check_image("colour", color)
        if normal is not None and albedo is None:
            raise ValueError("denoise: a normal guide needs an albedo guide as well (OIDN)")
        raw = sanitize(color)
        if not self._load():
            return Denoised(raw, None, self.failure)
        t0 = time.perf_counter()
        guides = {}
        for name, image, low in (("albedo", albedo, 0.0), ("normal", normal, -1.0)):
            if image is not None:
                image = np.asarray(image)
                _check_image(name, image, color.shape)
                guide = np.nan_to_num(np.asarray(image, np.float32), nan=0.0, posinf=1.0,
                                      neginf=low)
                guides[name] = np.ascontiguousarray(np.clip(guide, low, 1.0))
        height, width = raw.shape[:2]
        try:
            flt, buffers = self._filter_for(width, height, tuple(guides))
            nbytes = raw.nbytes
            buffers["color"].write(0, nbytes, raw)
            for name, guide in guides.items():
                buffers[name].write(0, nbytes, guide)
            t1 = time.perf_counter()
            flt.execute()
            self._raise_error("filter")
            t2 = time.perf_counter()
            out = np.empty_like(raw)
            buffers["output"].read(0, nbytes, out)
            t3 = time.perf_counter()
        except Exception as exc:
            self.failure = f"the denoiser failed ({exc}). Showing the image as rendered."
            self.close()
            return Denoised(raw, None, self.failure)
        out[~np.isfinite(out)] = 0.0
        np.maximum(out, 0.0, out=out)
        return Denoised(out, self.device, None,
                        {"upload_ms": 1e3 * (t1 - t0), "filter_ms": 1e3 * (t2 - t1),
                         "download_ms": 1e3 * (t3 - t2)})

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


def shared_denoiser(device: str = "auto", quality: str = "high") -> Denoiser:
    """One Denoiser a process per (device, quality): its weights and buffers are kept between
    frames and renders."""
    key = (device, quality)
    if key not in _shared:
        _shared[key] = Denoiser(device, quality)
    return _shared[key]
