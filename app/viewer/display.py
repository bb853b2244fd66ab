"""The picture in the window (glsl/display.frag): one method tone mapped, two side by side, or
the per-pixel error against the path tracer as a heat map; and the error's relative RMSE."""
from __future__ import annotations

import moderngl
import numpy as np

from radiance_probes.rendering.metrics import rrmse
from radiance_probes.gl.shaders import render_program, set_uniforms
from radiance_probes.scene.transfer import colormap_rgb

DISPLAY_MODE_IDS = {"image": 0, "split": 1, "error": 2}
HEAT_COLORMAP = "inferno"
BACKGROUND = (0.09, 0.09, 0.1)
MAIN_UNIT, OTHER_UNIT, HEAT_UNIT = 0, 1, 2


def relative_rmse(image: np.ndarray, reference: np.ndarray) -> float:
    """SPEC.md's error (app/bench/metrics.rrmse); NaN while the reference is still black."""
    try:
        return rrmse(image, reference)
    except ValueError:
        return float("nan")


def heat_colours(n: int = 256) -> np.ndarray:
    """The heat map's display colours, (n, 3), from no error to heat_max."""
    return colormap_rgb(HEAT_COLORMAP, n).astype(np.float32)


class DisplayPass:
    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.program = render_program(ctx, "fullscreen.vert", "display.frag")
        self.vao = ctx.vertex_array(self.program, [])
        self.heat = ctx.texture((256, 1), 3, heat_colours().tobytes(), dtype="f4")
        self.heat.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.heat.repeat_x = self.heat.repeat_y = False

    def draw(self, rect: tuple[int, int, int, int], mode: str, main, other=None,
             split_position: float = 0.5, exposure: float = 1.0,
             error_scale: float = 1.0) -> None:
        """Fills rect (x, y, w, h in framebuffer pixels, GL origin) of the bound framebuffer."""
        for texture, unit in ((main, MAIN_UNIT), (other, OTHER_UNIT)):
            if texture is not None:
                texture.use(unit)
        self.heat.use(HEAT_UNIT)
        set_uniforms(self.program, {
            "image_main": MAIN_UNIT, "image_other": OTHER_UNIT, "heat_colormap": HEAT_UNIT,
            "display_mode": DISPLAY_MODE_IDS[mode], "view_rect": tuple(float(v) for v in rect),
            "split_position": float(split_position), "exposure": float(exposure),
            "error_scale": float(error_scale), "background": BACKGROUND,
            "have_main": int(main is not None), "have_other": int(other is not None)})
        self.ctx.viewport = rect
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND | moderngl.CULL_FACE)
        self.vao.render(moderngl.TRIANGLES, vertices=3)

    def release(self) -> None:
        for obj in (self.vao, self.program, self.heat):
            obj.release()


def sample_stage(samples: int, max_samples: int) -> int:
    """The error view re-reads its images when this changes: at 1, 2, 4, 8, ... samples and at the
    last one, so an accumulation of N samples costs about log2(N) read-backs, not N."""
    return samples if samples >= max_samples else samples.bit_length()


class ErrorMeter:
    """Relative RMSE of a method against the path tracer. Reading both images back from the GPU
    costs more than a frame on a large view, so it is measured again only when either image has
    doubled its samples since (or finished, or restarted), not on every frame."""

    def __init__(self):
        self.key = None
        self.value = float("nan")
        self.reference_rms = 0.0
        self.reads = 0                 # read-backs so far (a test counts them)
        self.samples = (0, 0)          # the method's and the path tracer's samples when measured

    def update(self, session, method: str, max_samples: int) -> float:
        n, n_pt = session.samples(method), session.samples("pt")
        key = (method, sample_stage(n, max_samples), sample_stage(n_pt, max_samples),
               session.restarts)
        if key != self.key:
            self.reads += 1
            self.samples = (n, n_pt)
            image, reference = session.image(method), session.image("pt")
            if image is None or reference is None or image.shape != reference.shape:
                self.value, self.reference_rms = float("nan"), 0.0
            else:
                self.value = relative_rmse(image, reference)
                self.reference_rms = float(np.sqrt(np.mean(np.asarray(reference, np.float64) ** 2)))
            self.key = key
        return self.value
