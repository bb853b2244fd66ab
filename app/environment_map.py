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

from .scene_types import EnvironmentMapSpec, Scene, SceneError
from .twins.environment_map import Distribution, build_distribution

FORMATS = (".exr", ".hdr", ".pic", ".npy")
# The CDF texture is (W + 1) x (H + 1) texels and GL 4.3 guarantees 16384 per side.
MAX_WIDTH = 8192


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
