"""What a view will run once its probes are baked is made in the frame its bake begins, not in the
frame it first runs (issue 56: on the H200 a load's later frames paid 40 ms of shader compiles from
the driver's cache, 6 s with the cache empty, and 17-45 ms for the driver's first allocations of
path states, refine's halves and the uploads' buffers): Renderer.prepare, the touched buffers
(gl/memory.touch); the uploads' lent pixel buffer is tested with the other transfers
(tests/test_frame_pipeline.py)."""
from __future__ import annotations

from radiance_probes.io.scene_file import parse_scene

SCENE = {"volume": {"builtin": "cloud", "size": [12, 12, 12]}, "density_scale": 30.0,
         "albedo": 0.9, "camera": {"width": 24, "height": 16},
         "probes": {"grid": [2, 2, 2], "samples": 32, "fit": "box"}}


def _guided_passes(renderer):
    return {key: p for key, p in renderer._passes.items() if key[0] == "guided"}


def test_the_frame_a_bake_begins_in_makes_guided_for_both_halves(ctx):
    """refine's first frame of a load (no probes yet): that frame compiles guided's pass and gives
    both halves' path states their memory, at the view's size; the frames after it that run
    guided make no new pass."""
    from radiance_probes.viewer.frame.session import RenderSession
    s = RenderSession(ctx, parse_scene(SCENE), clock="wall")
    try:
        s.resize(24, 16)
        s.set_methods(["refine"])
        r = s.renderer
        assert not _guided_passes(r)
        times = s.step(64, True)
        assert "prepare" in times.parts and times.parts["prepare"][1] > 0.0
        made = _guided_passes(r)
        assert len(made) == 2                               # slot 0 and slot 1
        for tracer in made.values():
            assert tracer.states is not None
            assert tracer.states.size == 24 * 16 * tracer.state_bytes
        assert any(("GUIDED_LEVEL0", 1) in key[1] for key in r._raymarchers)   # level 0's
        view = s.views["refine"]
        for _ in range(200):
            s.step(64, True)
            if view.guided_samples > 0:
                break
        assert view.guided_samples > 0, s.refine_state()
        assert _guided_passes(r).keys() == made.keys()      # nothing new was compiled
        assert all(_guided_passes(r)[k] is made[k] for k in made)
    finally:
        s.release()


def test_prepare_without_probes_does_nothing_and_is_kept_on_a_second_call(ctx):
    from radiance_probes.rendering.renderer import Renderer
    r = Renderer(ctx, parse_scene(SCENE))
    try:
        r.prepare("guided", 24, 16, slots=(0, 1))
        assert not _guided_passes(r)          # no probe grid: its layout is not known yet
        r.prepare("pt", 24, 16)
        tracer = r.pass_for("pt")
        states = tracer.states
        assert states is not None and states.size == 24 * 16 * tracer.state_bytes
        r.prepare("pt", 24, 16)
        assert tracer.states is states        # the same size: kept
        r.prepare("pt", 12, 8)
        assert tracer.states.size == 12 * 8 * tracer.state_bytes
    finally:
        r.release()
