"""Writing a movie's frames: MP4 (H.264 through imageio-ffmpeg, whose wheel ships an ffmpeg
binary), an animated GIF (Pillow) or numbered PNGs in a folder. Frames are handed over as 8-bit
RGB arrays; MP4 and PNG frames are written by a background thread while the next frame renders.

`--out` names the format: `movie.mp4`, `movie.gif`, a folder (`frames/`, numbered
`frame_0000.png`, ...) or a pattern with a number field (`shots/bonsai_%04d.png`).
"""
from __future__ import annotations

import queue
import threading
from pathlib import Path

import numpy as np

FORMATS = ("mp4", "gif", "png")
QUEUE_FRAMES = 8          # frames waiting for the encoder at most (the renderer then waits)
DEFAULT_CRF = 18          # H.264 quality: visually lossless for these images
DEFAULT_PRESET = "fast"   # x264's speed against size: 1080p at well over 100 frames a second


class MovieError(ValueError):
    """A movie that cannot be written as asked (the format, the size, a missing encoder); the
    message names the option and the problem."""


def movie_format(path: str) -> str:
    """"mp4", "gif" or "png" from what `--out` names."""
    p = str(path)
    lower = p.lower()
    if lower.endswith(".mp4"):
        return "mp4"
    if lower.endswith(".gif"):
        return "gif"
    if lower.endswith(".png"):
        if "%" not in p:
            raise MovieError(f"--out {path}: numbered PNGs need a number field "
                             "(frames_%04d.png) or a folder (frames/)")
        return "png"
    if Path(p).suffix == "" or p.endswith(("/", "\\")):
        return "png"
    raise MovieError(f"--out {path}: expected a .mp4 or .gif file, a folder for numbered PNGs, "
                     "or a pattern such as frames_%04d.png")


def png_pattern(path: str) -> str:
    p = str(path)
    return p if p.lower().endswith(".png") else str(Path(p) / "frame_%04d.png")


def check_movie_output(path: str, width: int, height: int) -> str:
    """The format, after checking what can be checked before rendering: an MP4's even size
    (H.264 in yuv420p, which players expect, halves the colour resolution) and its encoder."""
    fmt = movie_format(path)
    if fmt == "mp4":
        if width % 2 or height % 2:
            raise MovieError(f"--out {path}: an MP4 (H.264, yuv420p, as media players expect) "
                             f"needs an even width and height, got {width}x{height}")
        try:
            import imageio_ffmpeg
            imageio_ffmpeg.get_ffmpeg_exe()
        except (ImportError, RuntimeError) as exc:
            raise MovieError(f"--out {path}: writing MP4 needs imageio-ffmpeg (pip install "
                             f"imageio-ffmpeg): {exc}; .gif or numbered PNGs need nothing more") from None
    if fmt == "png":
        pattern = png_pattern(path)
        try:
            pattern % 0
        except (TypeError, ValueError):
            raise MovieError(f"--out {path}: the pattern needs one integer field such as "
                             "%04d") from None
    return fmt


class MovieWriter:
    """Takes frames (add) and finishes the file (close). `fps` frames a second (MP4, GIF)."""

    def __init__(self, path: str, width: int, height: int, fps: float = 30.0,
                 crf: int = DEFAULT_CRF, preset: str = DEFAULT_PRESET):
        self.path = str(path)
        self.format = check_movie_output(path, width, height)
        self.size = (int(width), int(height))
        self.fps = float(fps)
        self.frames = 0
        self._gif: list = []
        self._error: BaseException | None = None
        self._queue: queue.Queue | None = None
        self._thread: threading.Thread | None = None
        if self.format == "mp4":
            import imageio_ffmpeg
            Path(self.path).parent.mkdir(parents=True, exist_ok=True)
            self._encoder = imageio_ffmpeg.write_frames(
                self.path, self.size, fps=self.fps, codec="libx264", pix_fmt_in="rgb24",
                pix_fmt_out="yuv420p", quality=None, macro_block_size=1,
                output_params=["-crf", str(int(crf)), "-preset", preset,
                               "-movflags", "+faststart"])
            self._encoder.send(None)   # starts ffmpeg
        elif self.format == "png":
            self._pattern = png_pattern(self.path)
            Path(self._pattern % 0).parent.mkdir(parents=True, exist_ok=True)
        if self.format in ("mp4", "png"):
            self._queue = queue.Queue(QUEUE_FRAMES)
            self._thread = threading.Thread(target=self._drain, daemon=True)
            self._thread.start()

    def _write(self, index: int, frame: np.ndarray) -> None:
        if self.format == "mp4":
            self._encoder.send(np.ascontiguousarray(frame, np.uint8).tobytes())
        else:
            from PIL import Image
            Image.fromarray(frame, "RGB").save(self._pattern % index)

    def _drain(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            if self._error is None:
                try:
                    self._write(*item)
                except BaseException as exc:   # reported by the next add or by close
                    self._error = exc

    def add(self, frame: np.ndarray) -> None:
        """One frame, (height, width, 3) uint8."""
        if frame.shape != (self.size[1], self.size[0], 3) or frame.dtype != np.uint8:
            raise MovieError(f"frame {self.frames}: expected {self.size[1]}x{self.size[0]}x3 "
                             f"uint8, got {frame.shape} {frame.dtype}")
        if self._error is not None:
            raise MovieError(f"writing {self.path} failed: {self._error}")
        if self.format == "gif":
            from PIL import Image
            self._gif.append(Image.fromarray(frame, "RGB"))
        else:
            self._queue.put((self.frames, frame))
        self.frames += 1

    def close(self) -> Path:
        """Finishes the file; returns its path (for PNGs, the folder of the first frame)."""
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join()
            self._thread = None
        if self.format == "mp4":
            self._encoder.close()
        elif self.format == "gif" and self._gif:
            Path(self.path).parent.mkdir(parents=True, exist_ok=True)
            self._gif[0].save(self.path, save_all=True, append_images=self._gif[1:],
                              duration=max(1, int(round(1000.0 / self.fps))), loop=0,
                              optimize=False)
            self._gif = []
        if self._error is not None:
            raise MovieError(f"writing {self.path} failed: {self._error}")
        return Path(self._pattern % 0).parent if self.format == "png" else Path(self.path)


def count_frames(path: str | Path) -> int:
    """Frames in a movie file as a media player decodes them (ffmpeg through imageio-ffmpeg for
    MP4, Pillow for GIF)."""
    p = Path(path)
    if p.suffix.lower() == ".gif":
        from PIL import Image
        with Image.open(p) as im:
            return int(im.n_frames)
    import imageio_ffmpeg
    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(p))
    return int(frames)
