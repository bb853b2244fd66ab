"""Environment map files (SPEC.md's `"environment": {"map": ...}`): read, checked and turned into
the sampling distribution on the CPU, before any GPU work. Every problem is one SceneError that
names the file: missing, unreadable or truncated, an unknown format, not 2:1, too large, negative
or non-finite radiance.

Formats: OpenEXR (`.exr`, through the OpenEXR package: R, G, B channels or Y for grey; half or
float), Radiance RGBE (`.hdr`/`.pic`, through OpenCV's reader, opencv-python-headless) and NumPy
`.npy` float arrays (H, W, 3) or (H, W).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from radiance_probes.scene.types import EnvironmentMapSpec, Scene, SceneError

FORMATS = (".exr", ".hdr", ".pic", ".npy")
# The CDF texture is (W + 1) x (H + 1) texels and GL 4.3 guarantees 16384 per side.
MAX_WIDTH = 8192


LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


@dataclass(frozen=True)
class Distribution:
    """What the GPU samples from (see the module docstring)."""
    pdf_uv: np.ndarray      # (H, W) float64: density over (u, v) in [0, 1]^2, mean 1
    conditional: np.ndarray  # (H, W + 1) float64: row i's CDF over its columns, 0 ... 1
    marginal: np.ndarray     # (H + 1,) float64: CDF over rows, 0 ... 1

    @property
    def shape(self) -> tuple[int, int]:
        return self.pdf_uv.shape

    def cdf_texture(self) -> np.ndarray:
        """(H + 1, W + 1) float32: conditional CDFs in rows 0..H-1, the marginal CDF in row H."""
        h, w = self.shape
        tex = np.ones((h + 1, w + 1), np.float32)
        tex[:h] = self.conditional
        tex[h, : h + 1] = self.marginal
        return tex


def _cdf(weights: np.ndarray) -> np.ndarray:
    """CDFs along the last axis, starting at 0 and ending at exactly 1 (uniform where all 0)."""
    n = weights.shape[-1]
    total = weights.sum(axis=-1, keepdims=True)
    uniform = np.broadcast_to(np.arange(1, n + 1) / n, weights.shape)
    safe = np.where(total > 0, total, 1.0)
    c = np.where(total > 0, np.cumsum(weights, axis=-1) / safe, uniform)
    c[..., -1] = 1.0
    return np.concatenate([np.zeros(weights.shape[:-1] + (1,)), c], axis=-1)


def pixel_weights(image: np.ndarray) -> np.ndarray:
    """(H, W) sampling weights: the bilinear luminance's integral over each pixel times its solid angle."""
    h, w = image.shape[:2]
    lum = np.asarray(image, np.float64) @ LUMINANCE
    lum = (np.roll(lum, 1, axis=1) + 6.0 * lum + np.roll(lum, -1, axis=1)) / 8.0
    up = np.concatenate([lum[:1], lum[:-1]], axis=0)
    down = np.concatenate([lum[1:], lum[-1:]], axis=0)
    lum = (up + 6.0 * lum + down) / 8.0
    band = np.cos(np.pi * np.arange(h) / h) - np.cos(np.pi * np.arange(1, h + 1) / h)
    weights = lum * band[:, None]
    if not weights.sum() > 0:
        weights = np.broadcast_to(band[:, None], (h, w)).copy()  # a black map: uniform over the sphere
    return weights


def build_distribution(image: np.ndarray) -> Distribution:
    weights = pixel_weights(image)
    return Distribution(pdf_uv=weights / weights.mean(), conditional=_cdf(weights),
                        marginal=_cdf(weights.sum(axis=1)))


@dataclass(frozen=True)
class EnvironmentMap:
    path: Path
    image: np.ndarray            # (H, W, 3) float32 linear RGB radiance (before the scene's scale)
    distribution: Distribution

    @property
    def grey(self) -> bool:
        return bool(np.array_equal(self.image[..., 0], self.image[..., 1])
                    and np.array_equal(self.image[..., 0], self.image[..., 2]))


def resolve_path(path: str, base_dir: str | None) -> Path:
    """Relative to the scene file's folder first (like volume paths), else to the working folder."""
    p = Path(path).expanduser()
    if p.is_absolute() or base_dir is None:
        return p
    alt = Path(base_dir) / p
    return alt if alt.is_file() or not p.is_file() else p


def _read_exr(p: Path) -> np.ndarray:
    try:
        import OpenEXR
    except ImportError:
        raise SceneError(f"{p}: reading EXR needs the OpenEXR package: pip install OpenEXR") from None
    try:
        with OpenEXR.File(str(p)) as f:
            channels = {name: np.asarray(c.pixels) for name, c in f.channels().items()}
    except Exception as exc:  # the library raises RuntimeError for unreadable and truncated files
        msg = " ".join(str(exc).split()) or type(exc).__name__
        raise SceneError(f"{p}: cannot read the environment map (not a complete OpenEXR file: "
                         f"{msg})") from None
    for name in ("RGB", "RGBA"):
        if name in channels:
            return channels[name][..., :3]
    if all(c in channels for c in "RGB"):
        return np.stack([channels[c] for c in "RGB"], axis=-1)
    if "Y" in channels:
        return channels["Y"]
    raise SceneError(f"{p}: the environment map has no R, G, B (or Y) channels "
                     f"(it has {', '.join(sorted(channels)) or 'none'})")


def _read_hdr(p: Path) -> np.ndarray:
    try:
        import cv2
    except ImportError:
        raise SceneError(f"{p}: reading Radiance .hdr needs OpenCV: pip install "
                         "opencv-python-headless") from None
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)  # errors come back as None
    data = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    if data is None or data.ndim != 3 or data.shape[-1] != 3 or data.dtype != np.float32:
        raise SceneError(f"{p}: cannot read the environment map (not a complete Radiance RGBE "
                         "file)")
    return data[..., ::-1]   # OpenCV's BGR order


def _read_npy(p: Path) -> np.ndarray:
    try:
        data = np.load(p, allow_pickle=False)
    except Exception as exc:
        msg = " ".join(str(exc).split()) or type(exc).__name__
        raise SceneError(f"{p}: cannot read the environment map (not a complete .npy file: "
                         f"{msg})") from None
    if not isinstance(data, np.ndarray) or not (np.issubdtype(data.dtype, np.floating)
                                                or np.issubdtype(data.dtype, np.integer)):
        raise SceneError(f"{p}: the environment map must be a float array, got "
                         f"{getattr(data, 'dtype', type(data).__name__)}")
    return data


def read_environment_map(p: Path) -> np.ndarray:
    """The file's radiance as (H, W, 3) float32, checked; SceneError naming `p` otherwise."""
    if not p.is_file():
        raise SceneError(f"{p}: environment map file not found")
    suffix = p.suffix.lower()
    if suffix == ".exr":
        data = _read_exr(p)
    elif suffix in (".hdr", ".pic"):
        data = _read_hdr(p)
    elif suffix == ".npy":
        data = _read_npy(p)
    else:
        raise SceneError(f"{p}: unknown environment map format '{suffix}' (known: "
                         f"{', '.join(FORMATS)})")
    if data.ndim == 2:
        data = np.repeat(data[..., None], 3, axis=-1)
    if data.ndim != 3 or data.shape[-1] not in (3, 4):
        raise SceneError(f"{p}: the environment map must be an (H, W, 3) RGB image, got shape "
                         f"{tuple(data.shape)}")
    h, w = data.shape[:2]
    if h < 1 or w != 2 * h:
        raise SceneError(f"{p}: the environment map must be twice as wide as it is high "
                         f"(equirectangular, 2:1), got {w} x {h}")
    if w > MAX_WIDTH:
        raise SceneError(f"{p}: the environment map is {w} x {h}; at most {MAX_WIDTH} x "
                         f"{MAX_WIDTH // 2} is supported")
    rgb = np.asarray(data[..., :3], np.float64)
    bad = ~np.isfinite(rgb)
    if bad.any():
        i, j, _ = np.argwhere(bad)[0]
        raise SceneError(f"{p}: the environment map has {int(bad.sum())} non-finite values (NaN or "
                         f"Inf; the first at row {i}, column {j})")
    if (rgb < 0).any():
        i, j, _ = np.argwhere(rgb < 0)[0]
        raise SceneError(f"{p}: the environment map has {int((rgb < 0).sum())} negative values "
                         f"(the first at row {i}, column {j}: {rgb[i, j].tolist()})")
    if rgb.max() > np.finfo(np.float32).max:
        raise SceneError(f"{p}: the environment map has values beyond float32's range")
    return np.ascontiguousarray(rgb, np.float32)


_CACHE: dict[tuple, EnvironmentMap] = {}


def load_environment_map(spec: EnvironmentMapSpec, base_dir: str | None = None) -> EnvironmentMap:
    """The map a scene names with its distribution; cached by file, size and modification time."""
    p = resolve_path(spec.path, base_dir)
    try:
        st = p.stat()
        key = (str(p.resolve()), st.st_size, st.st_mtime_ns)
    except OSError:
        key = None
    if key is not None and key in _CACHE:
        return _CACHE[key]
    image = read_environment_map(p)
    env = EnvironmentMap(p, image, build_distribution(image))
    if key is not None:
        _CACHE.clear()   # one map at a time is plenty; a viewer switching maps reloads
        _CACHE[key] = env
    return env


def load_scene_environment(scene: Scene) -> EnvironmentMap | None:
    """The scene's environment map, or None for a constant environment."""
    if scene.environment_map is None:
        return None
    return load_environment_map(scene.environment_map, scene.base_dir)
