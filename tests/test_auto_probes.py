"""`auto` (app/rendering/probes/auto.py): the cheapest setting meeting the target, measured against
a path-traced pilot; says so when nothing meets it; leaves the renderer's scene unchanged."""
import pytest

from radiance_probes.rendering.probes.auto import choose_probes
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import parse_scene

SCENE = {"volume": {"builtin": "cloud", "size": [20, 20, 20]}, "density_scale": 40.0,
         "camera": {"eye": [0, 0.3, 2.2], "width": 32, "height": 32}}


@pytest.fixture()
def renderer(ctx):
    r = Renderer(ctx, parse_scene(SCENE))
    yield r
    r.release()


def test_auto_takes_the_first_candidate_meeting_the_target(renderer):
    before = renderer.scene
    choice = choose_probes(renderer, 0.5, "raymarch", grids=(2, 4), walks=(16, 64), pilot_side=16,
                           max_pilot_spp=512)
    assert choice.met and choice.rrmse <= 0.5
    assert choice.trials[0]["grid"] == 2 and choice.trials[0]["walks"] == 16
    p = choice.scene.probes
    assert (p.grid, p.samples) == ((2, 2, 2), 16) and p.precision == "rgba16f" and p.fit == "visible"
    assert renderer.scene == before
    assert "target 0.5000 met" in choice.report()
    # a second search finds the probes already baked: its trials still say what they cost
    again = choose_probes(renderer, 0.5, "raymarch", grids=(2,), walks=(16,), pilot_side=16,
                          max_pilot_spp=512)
    assert all(t["bake_ms"] > 0 for t in choice.trials + again.trials)
    assert again.search_ms > again.trials[0]["bake_ms"]


def test_auto_says_when_the_target_is_out_of_reach(renderer):
    choice = choose_probes(renderer, 1e-4, "probes", grids=(2, 3), walks=(16,), pilot_side=12,
                           max_pilot_spp=256, frames=4)
    assert not choice.met
    assert choice.rrmse == min(t["rrmse"] for t in choice.trials)
    assert len(choice.trials) == 2 and "NOT met" in choice.report()
    assert any("pilot stopped" in r for r in choice.reasons)


def test_auto_rejects_a_meaningless_target(renderer):
    with pytest.raises(ValueError, match="target"):
        choose_probes(renderer, 0.0)


def test_auto_tries_no_grid_finer_than_the_volume(ctx):
    """Grids of more than two probes a voxel along the volume's longest axis are skipped, and the
    report says so (the defaults go up to 256^3, which a small volume cannot use)."""
    r = Renderer(ctx, parse_scene({**SCENE, "volume": {"builtin": "cloud", "size": [3, 2, 2]}}))
    try:
        choice = choose_probes(r, 1e-4, "raymarch", grids=(2, 6, 7, 12), walks=(16,),
                               pilot_side=12, max_pilot_spp=128, frames=1)
    finally:
        r.release()
    assert [t["grid"] for t in choice.trials] == [2, 6]
    assert any("grids up to 6^3" in reason for reason in choice.reasons), choice.reasons
