"""Every render method, registered once: its name, what it is for in one line, and the properties
the rest of the code asks about (does it read the probes, the light grid; is it noisy; where can
it be chosen; which settings are its own).

The renderers (app/rendering/renderer.py), the command line, the viewer, movies, the bench, the
Python API and the scene schema all read this table, so a new method is one entry here plus the
code that renders it (docs/design.md, "Adding a render method"). The module imports nothing of the
package, so the lowest layer (the scene's types) can import the names too.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Method:
    """One render method."""
    name: str
    doc: str                        # one line: what it is and what it is for
    noisy: bool                     # Monte Carlo: samples accumulate, and the denoiser can filter it
    needs_probes: bool              # reads the probes (a bake comes first)
    needs_light_grid: bool          # always reads the sun's light grid (the path-traced methods
    #                                 also do where shadow_tracking is "residual")
    default_spp: int                # samples (raymarched frames) a still image takes unless told
    probe_lighting: int = 0         # glsl/pathtrace.comp's PROBE_LIGHTING: 0 the path tracer's own
    #                                 light, 1 the probes at the gather event with the sun by a
    #                                 shadow ray, 2 the sun's transmittance from the probes too
    path_states: bool = True        # a path-state pass (pathtrace.comp: a PathState per pixel)
    signed: bool = False            # its image may dip below zero (guided's level 1 subtracts)
    parts: tuple[str, ...] = ()     # made of other methods' images (refine: raymarch, then guided);
    #                                 no single accumulation holds it (Renderer.begin refuses it)
    viewer_key: str | None = None   # the viewer's key for it (None: not offered in the viewer)
    movie: bool = False             # a movie (animate, the viewer's recorder) can render it
    options: tuple[str, ...] = ()   # RenderSettings fields that act on this method alone

    @property
    def composite(self) -> bool:
        return bool(self.parts)

    @property
    def sample_word(self) -> str:
        """What its samples are called in captions and reports: the raymarcher renders whole
        frames ("frames"), the others samples per pixel ("spp")."""
        return "spp" if self.noisy else "frames"


REFERENCE = "pt"   # the exact image every other method's error is measured against

_TABLE = (
    Method("pt", "the reference: unbiased volumetric path tracing, noisy until many samples",
           noisy=True, needs_probes=False, needs_light_grid=False, default_spp=64,
           viewer_key="1", movie=True),
    Method("probes", "the camera ray traced to a scattering event, the probes for the light after "
                     "it; noisy, converges to the probes' small error",
           noisy=True, needs_probes=True, needs_light_grid=False, default_spp=64,
           probe_lighting=1, viewer_key="2", movie=True, options=("gather_event",)),
    Method("probes-only", "as probes, the sun's shadow read from the probes too (comparisons)",
           noisy=True, needs_probes=True, needs_light_grid=False, default_spp=64,
           probe_lighting=2, viewer_key="3", movie=True),
    Method("raymarch", "deterministic marching over the probes and the light grid: a clean "
                       "image every frame (interaction)",
           noisy=False, needs_probes=True, needs_light_grid=True, default_spp=4,
           path_states=False, viewer_key="4", movie=True,
           options=("raymarch_stage", "raymarch_step")),
    Method("guided", "the path tracer's image (unbiased) with the probes' prediction as a "
                     "control variate (experiments)",
           noisy=True, needs_probes=True, needs_light_grid=True, default_spp=64, signed=True,
           options=("guided_level0_ratio", "guided_direction_control")),
    Method("refine", "the raymarcher's image at once, replaced by guided's once its error, "
                     "estimated from two half-images, is the smaller",
           noisy=True, needs_probes=True, needs_light_grid=True, default_spp=64,
           path_states=False, parts=("raymarch", "guided"), viewer_key="5"),
)

METHODS: dict[str, Method] = {m.name: m for m in _TABLE}
NAMES: tuple[str, ...] = tuple(METHODS)
# The methods one accumulation holds (the Renderer's frame API: begin, add_samples; the bench's
# sweeps and reports).
ACCUMULATED: tuple[str, ...] = tuple(m.name for m in _TABLE if not m.composite)
# What the viewer offers (its keys, panel, --method, the scene's viewer.method), and movies.
VIEWER_METHODS: tuple[str, ...] = tuple(m.name for m in _TABLE if m.viewer_key is not None)
MOVIE_METHODS: tuple[str, ...] = tuple(m.name for m in _TABLE if m.movie)
# The path tracer's variants that read the probes (glsl/pathtrace.comp's PROBE_LIGHTING).
PROBE_LIT: tuple[str, ...] = tuple(m.name for m in _TABLE if m.probe_lighting)


def method(name: str) -> Method:
    """The method of that name, or ValueError naming the known ones."""
    try:
        return METHODS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown method {name!r} (known: {', '.join(NAMES)})") from None


def listing(names: tuple[str, ...] = NAMES) -> str:
    """'pt: the reference ...; probes: ...' for help texts."""
    return "; ".join(f"{n}: {METHODS[n].doc}" for n in names)
