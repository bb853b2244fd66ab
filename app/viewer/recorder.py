"""The viewer's movie recorder (the 'Bookmarks and movie' panel, ctrl+r): the same movie as
`radiance-probes animate` (app/movie/frames.py), a turntable or a flight through the bookmarks, rendered
one movie frame per window frame by the viewer's own renderer (the probes it has baked serve the
whole movie), so the window stays live and shows the progress."""
from __future__ import annotations

from dataclasses import replace

from radiance_probes.frontend.colorbar import scene_colorbar_overlay
from radiance_probes.movie.frames import MovieFrames, movie_cameras
from radiance_probes.movie.writer import MovieWriter, check_movie_output

MOVIE_MODES = ("turntable", "keyframes")


class MovieRecorder:
    @staticmethod
    def default_settings() -> dict:
        return {"mode": "turntable", "degrees": 360.0, "frames": 120, "method": "raymarch",
                "spp": 16, "width": 640, "height": 480, "fps": 30.0, "out": "movie.mp4",
                "colorbar": False}

    def __init__(self, renderer, scene, volume, settings: dict):
        s = dict(settings)
        scene = scene.replace(camera=replace(scene.camera, width=int(s["width"]),
                                             height=int(s["height"])))
        check_movie_output(s["out"], scene.camera.width, scene.camera.height)
        cameras = movie_cameras(scene, int(s["frames"]),
                                float(s["degrees"]) if s["mode"] == "turntable" else None,
                                [] if s["mode"] == "keyframes" else None)
        overlay = (scene_colorbar_overlay(scene.camera.width, scene.camera.height, scene, volume)
                   if s["colorbar"] else None)
        self.settings = s
        self.frames = MovieFrames(renderer, cameras, s["method"], int(s["spp"]), overlay=overlay)
        self.writer = MovieWriter(s["out"], scene.camera.width, scene.camera.height, fps=s["fps"])
        self.total = len(cameras)
        self.path = None

    def step(self) -> bool:
        """Renders and writes the next frame; True once the movie is done (and its file closed)."""
        pixels, _ = self.frames.frame()
        self.writer.add(pixels)
        if self.frames.done:
            self.stop()
            return True
        return False

    def progress(self) -> dict:
        return {"done": self.frames.next, "total": self.total, "out": self.settings["out"],
                "bakes": self.frames.bakes}

    def stop(self):
        """Closes the file with the frames so far; its path."""
        if self.path is None:
            try:
                self.path = self.writer.close()
            finally:
                self.frames.release()
        return self.path

    def finish_note(self) -> str:
        return (f"recorded {self.total} frames to {self.path} (probes baked "
                f"{self.frames.bakes}x for the movie)")
