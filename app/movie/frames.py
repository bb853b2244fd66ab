"""Movies: `radiance-probes animate SCENE`, the viewer's recorder and `bench --preset movie` all
render a camera path (app/scene/camera_path.py) here, frame after frame, into a MovieWriter.

The probes (and the light grid) are baked once, before the first frame: a camera move never
touches the bake key (Renderer.bake_key), so every frame reads the same probes, and a movie of
raymarched frames costs one bake plus a raymarch per frame. Each frame is its own accumulation of
`spp` samples (for the raymarcher, jittered frames) with the same seed, tone mapped on the GPU and
handed to the encoder, which writes while the next frame renders.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from radiance_probes.scene.camera_path import keyframes, turntable
from radiance_probes.methods import METHODS
from radiance_probes.scene.types import CameraSpec, Scene


@dataclass
class MovieResult:
    path: str
    frames: int
    width: int
    height: int
    method: str
    spp: int
    bakes: int                 # probe bakes the movie ran (1 for a probe method, 0 for pt)
    bake_ms: float             # their GPU time, the light grid's included
    render_ms: float           # GPU time of the frames' samples
    wall_s: float              # the whole movie on the host's clock: bake, frames, encoding
    kept: dict = field(default_factory=dict)   # frame index -> linear image (bench)
    denoise_note: str | None = None            # why frames were not denoised, where asked

    def summary(self) -> str:
        return (f"{self.frames} frames {self.width}x{self.height}, {self.method} at {self.spp} "
                f"{'spp' if METHODS[self.method].noisy else 'frames'} each: {self.wall_s:.2f} s in "
                f"all; probes baked {self.bakes}x ({self.bake_ms:.1f} ms GPU), frames "
                f"{self.render_ms:.1f} ms GPU ({self.render_ms / max(self.frames, 1):.2f} ms a frame)")


def movie_cameras(scene: Scene, frames: int, turntable_degrees: float | None = None,
                  bookmarks: list[str] | None = None) -> list[CameraSpec]:
    """The cameras of a movie: a turntable from the scene's camera, or a flight through the named
    bookmarks (all of the scene's, in order, when `bookmarks` is an empty list)."""
    if turntable_degrees is not None:
        return turntable(scene.camera, turntable_degrees, frames)
    if bookmarks is None:
        raise ValueError("a movie needs a turntable or keyframes through bookmarks")
    known = {b.name: b for b in scene.bookmarks}
    if not known:
        raise ValueError("keyframes: the scene has no bookmarks (save some in the viewer with "
                         "ctrl+1 .. ctrl+9, or add \"bookmarks\" to the scene file)")
    names = bookmarks or [b.name for b in scene.bookmarks]
    missing = [n for n in names if n not in known]
    if missing:
        raise ValueError(f"keyframes: no bookmark named {', '.join(map(repr, missing))} (the scene "
                         f"has {', '.join(map(repr, known))})")
    cams = [known[n].camera(scene.camera) for n in names]
    return keyframes(cams, frames, base=scene.camera)


class MovieFrames:
    """Renders a movie's frames one at a time with a renderer it borrows (the CLI runs them all
    at once; the viewer's recorder one per window frame, so the window stays live). The probes are
    baked before the first frame if they are not current; a camera move never makes them stale.
    The renderer's scene and accumulation are given back after every frame."""

    def __init__(self, renderer, cameras: list[CameraSpec], method: str = "raymarch",
                 spp: int = 16, seed: int = 0, exposure: float = 1.0,
                 samples_per_pass: int = 16, overlay=None, times: list[int] | None = None,
                 denoise: bool = False):
        """`times`: a time series' step of each frame (None: the scene's step throughout);
        `denoise`: each frame through the denoiser (Renderer.denoise, "auto" guides; a note in
        `denoise_note` and the raw frames where it cannot run). A
        frame on another step than the last bakes that step's probes (restarted from the last
        step's: Renderer.bake; a finished bake is the same either way)."""
        from radiance_probes.rendering.methods.accumulation import Accumulation
        from radiance_probes.rendering.frame_readback import FrameReadback
        self.renderer, self.cameras, self.method = renderer, list(cameras), method
        self.spp, self.seed, self.exposure = int(spp), int(seed), float(exposure)
        self.samples_per_pass, self.overlay = int(samples_per_pass), overlay
        self.width, self.height = self.cameras[0].width, self.cameras[0].height
        self.acc = Accumulation(renderer.ctx, self.width, self.height)
        self.readback = FrameReadback(renderer.ctx)
        self.next = 0
        self.bakes, self.bake_ms, self.render_ms = 0, 0.0, 0.0
        if times is not None and len(times) != len(self.cameras):
            raise ValueError(f"{len(times)} time steps for {len(self.cameras)} frames")
        self.times = None if times is None else [int(t) for t in times]
        self.scene_time = renderer.scene.time   # given back when the movie is done
        self.denoise = denoise and METHODS[method].noisy   # (the raymarcher's frames are not)
        self.denoise_note: str | None = None

    @property
    def done(self) -> bool:
        return self.next >= len(self.cameras)

    def frame(self, keep_linear: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """The next frame as 8-bit RGB (the overlay drawn in), and its linear image if asked."""
        r = self.renderer
        scene = r.scene
        step = scene.time if self.times is None else self.times[self.next]
        with r.lend(self.acc):
            try:
                r.set_scene(scene.replace(camera=self.cameras[self.next], time=step))
                if r.needs_probes(self.method) and not r.probes_current():
                    self.bake_ms += r.bake(self.seed)     # before the first frame only (tests count)
                    self.bakes += 1
                if r.needs_light(self.method):   # counted with the bake, not the frames
                    self.bake_ms += r.bake_light()
                acc = r.begin(self.method, seed=self.seed)
                while acc.samples < self.spp:
                    self.render_ms += r.add_samples(min(self.samples_per_pass,
                                                        self.spp - acc.samples))
                if self.denoise:
                    from radiance_probes.rendering.denoise.filter import choose_guides
                    from radiance_probes.rendering.tonemap import to_uint8
                    has_probes = r.needs_probes(self.method) and r.probes_shown()
                    d, _ = r.denoise(None, choose_guides("auto", self.spp, has_probes))
                    self.denoise_note = self.denoise_note or d.note
                    linear = d.image if keep_linear else None
                    pixels = to_uint8(d.image, self.exposure)
                else:
                    linear = acc.read() if keep_linear else None
                    pixels = self.readback.read(acc, self.exposure)
            finally:
                # the step stays until the movie is done: going back between frames would re-bake
                r.set_scene(scene.replace(time=step))
        if self.overlay is not None:
            pixels = self.overlay.apply(pixels)
        self.next += 1
        return pixels, linear

    def release(self) -> None:
        if self.renderer.scene.time != self.scene_time:
            self.renderer.set_scene(self.renderer.scene.replace(time=self.scene_time))
        self.acc.release()
        self.readback.release()


def render_movie(renderer, cameras: list[CameraSpec], writer, method: str = "raymarch",
                 spp: int = 16, seed: int = 0, exposure: float = 1.0, samples_per_pass: int = 16,
                 overlay=None, progress=None, keep: tuple[int, ...] = (),
                 times: list[int] | None = None, denoise: bool = False) -> MovieResult:
    """Renders every camera into `writer` (None: frames are not written, only kept or timed);
    `overlay`: a colorbar.ColorbarOverlay laid over each frame; `progress(done, total)` after each
    frame; `keep`: frame indices whose linear images come back in MovieResult.kept."""
    start = time.perf_counter()
    frames = MovieFrames(renderer, cameras, method, spp, seed, exposure, samples_per_pass, overlay,
                         times, denoise)
    kept = {}
    try:
        while not frames.done:
            index = frames.next
            pixels, linear = frames.frame(keep_linear=index in keep)
            if linear is not None:
                kept[index] = linear
            if writer is not None:
                writer.add(pixels)
            if progress is not None:
                progress(index + 1, len(cameras))
        path = str(writer.close()) if writer is not None else ""
    finally:
        frames.release()
    return MovieResult(path=path, frames=len(cameras), width=frames.width, height=frames.height,
                       method=method, spp=spp, bakes=frames.bakes, bake_ms=frames.bake_ms,
                       render_ms=frames.render_ms, wall_s=time.perf_counter() - start, kept=kept,
                       denoise_note=frames.denoise_note)


def series_steps(steps: int, frames: int) -> list[int]:
    """The step each of `frames` frames shows of a series of `steps`: evenly through the series,
    first to last (each step held frames / steps frames)."""
    if steps < 2:
        raise ValueError("the volume has no time axis (one step)")
    return [min(steps - 1, i * steps // frames) for i in range(frames)]


def sized(cameras: list[CameraSpec], width: int, height: int) -> list[CameraSpec]:
    return [replace(c, width=width, height=height) for c in cameras]


def frame_count_note(path: str, expected: int) -> str | None:
    """A line saying how many frames a media player finds in the file, when it can be counted
    (MP4 through ffmpeg, GIF through Pillow); a mismatch is an error line."""
    from radiance_probes.movie.writer import count_frames
    if not str(path).lower().endswith((".mp4", ".gif")):
        return None
    try:
        n = count_frames(path)
    except Exception as exc:   # a decoder's failure says the file is broken
        return f"error: {path} could not be read back ({exc})"
    if n != expected:
        return f"error: {path} holds {n} frames, not {expected}"
    return f"{path}: {n} frames as a media player reads them"
