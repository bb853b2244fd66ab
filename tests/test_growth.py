"""No growth: 1000 transfer-function edits, each with a re-bake and a frame, and 1000 volume
reloads, each with a frame, in one process, leave as many live GPU objects as after the first
few, drop none unreleased, and grow neither host memory nor (on NVIDIA) the driver's used memory.

GPU objects are counted through the context: every object a moderngl Context makes is followed
(live: not released), and the context runs in moderngl's "context_gc" mode, where an object
dropped without release() lands in ctx.objects instead of being freed silently. llvmpipe's GPU
memory is host memory, so the process's resident size covers it there; on NVIDIA the driver's
GL_NVX_gpu_memory_info query is read too.

Small on purpose (a 6^3 volume, 2^3 probes with one walk, 4 x 4 pixels): what leaks here leaks
per edit whatever the size. Measured on llvmpipe with two cores: about 12 s for the edits and
3 s for the reloads. A transfer texture left unreleased per edit fails the first test (checked
by hand when this was written).
"""
from __future__ import annotations

import gc
import os
import weakref

import moderngl
import numpy as np
import pytest

from radiance_probes.gl.memory import gpu_available_bytes
from radiance_probes.rendering.renderer import Renderer
from radiance_probes.io.scene_file import parse_scene

ITERATIONS = 1000
WARM_UP = 40                 # first edits compile each shader variant and fill caches
HOST_GROWTH_LIMIT = 24 << 20  # bytes of resident memory; one leaked table per edit would be more
GPU_GROWTH_LIMIT = 16 << 20

CREATORS = ("buffer", "texture", "texture3d", "texture_array", "texture_cube", "depth_texture",
            "renderbuffer", "depth_renderbuffer", "framebuffer", "program", "compute_shader",
            "vertex_array", "simple_vertex_array", "query", "sampler", "scope")

BASE = {"volume": {"builtin": "cloud", "size": [6, 6, 6]}, "camera": {"width": 4, "height": 4},
        "probes": {"grid": 2, "samples": 1}, "max_bounces": 2, "density_scale": 20.0}


class ObjectCounter:
    """Follows every GPU object the context makes (weak references: following keeps nothing alive)."""

    def __init__(self, monkeypatch):
        self.made: list[weakref.ref] = []
        for name in CREATORS:
            original = getattr(moderngl.Context, name, None)
            if original is None:
                continue
            monkeypatch.setattr(moderngl.Context, name, self._wrap(original))

    def _wrap(self, original):
        def create(ctx, *args, **kwargs):
            obj = original(ctx, *args, **kwargs)
            self.made.append(weakref.ref(obj))
            return obj
        return create

    def live(self) -> int:
        self.made = [r for r in self.made if r() is not None]
        return sum(not isinstance(r().mglo, moderngl.InvalidObject) for r in self.made)


def resident_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def dropped_unreleased(ctx) -> int:
    """Objects garbage-collected without release(): in "context_gc" mode moderngl queues every
    collected object's handle in ctx.objects, released ones as InvalidObject."""
    gc.collect()
    return sum(not isinstance(o, moderngl.InvalidObject) for o in ctx.objects)


@pytest.fixture
def counted(ctx, monkeypatch):
    counter = ObjectCounter(monkeypatch)
    ctx.gc_mode = "context_gc"
    try:
        yield counter
        assert dropped_unreleased(ctx) == 0, "GPU objects were dropped without release()"
    finally:
        gc.collect()
        while ctx.objects:
            handle = ctx.objects.popleft()
            if not isinstance(handle, moderngl.InvalidObject):
                handle.release()
        ctx.gc_mode = None


def assert_all_released(ctx, counter) -> None:
    """After Renderer.release() nothing it made is alive but the majorant grid's build pass,
    which is compiled once per context and shared by design (app/rendering/grids/majorant_grid.py)."""
    from radiance_probes.rendering.grids.majorant_grid import _programs
    shared = _programs.get(ctx)
    alive = [r() for r in counter.made if r() is not None
             and not isinstance(r().mglo, moderngl.InvalidObject) and r() is not shared]
    assert not alive, f"left alive after release(): {[type(o).__name__ for o in alive]}"


def check_no_growth(ctx, counter, step) -> None:
    for i in range(WARM_UP):
        step(i)
    gc.collect()
    live0, host0, gpu0 = counter.live(), resident_bytes(), gpu_available_bytes(ctx)
    assert live0 > 0   # the counter does see the renderer's objects
    for i in range(WARM_UP, WARM_UP + ITERATIONS):
        step(i)
    gc.collect()
    assert counter.live() == live0, f"live GPU objects {live0} -> {counter.live()}"
    assert dropped_unreleased(ctx) == 0, "GPU objects were dropped without release()"
    grown = resident_bytes() - host0
    assert grown < HOST_GROWTH_LIMIT, f"resident memory grew by {grown / 2**20:.1f} MiB"
    if gpu0 is not None:
        used = gpu0 - gpu_available_bytes(ctx)
        assert used < GPU_GROWTH_LIMIT, f"the driver reports {used / 2**20:.1f} MiB more in use"


def test_transfer_function_edits_with_rebakes_do_not_grow(ctx, counted):
    """Opacity curves that move the visible region (so the fitted grid's size changes), explicit
    RGBA rows, grey and colour maps (one or three probe channels): the probe textures, the
    transfer texture, the majorant grid and the light grid are replaced, never added to."""
    renderer = Renderer(ctx, parse_scene(BASE))

    def step(i: int) -> None:
        if i % 5 == 4:
            a = (i % 11) / 11
            tf = {"rgba": [[1, 1, 1, 0], [0.5, 0.5, 0.5, a], [1, 1, 1, 1]]}
        else:
            tf = {"colormap": ("plasma", "grey", "viridis")[i % 3],
                  "opacity": [[0, 0], [0.05 + 0.6 * (i % 7) / 7, 0.0], [1, 1 - (i % 4) / 8]]}
        renderer.set_scene(parse_scene({**BASE, "transfer_function": tf}))
        renderer.bake()
        assert renderer.probes_current()
        renderer.render("raymarch" if i % 2 else "probes", spp=1)

    try:
        check_no_growth(ctx, counted, step)
    finally:
        renderer.release()
    assert_all_released(ctx, counted)


def test_volume_reloads_do_not_grow(ctx, counted, tmp_path):
    """Volumes loaded from files of two sizes and a built-in, alternately: the volume texture,
    its macrocell grid and the stale probes are replaced, never added to."""
    rng = np.random.default_rng(1)
    files = []
    for k, shape in enumerate(((6, 6, 6), (5, 7, 6))):
        p = tmp_path / f"v{k}.npy"
        np.save(p, rng.random(shape).astype(np.float32))
        files.append(str(p))
    renderer = Renderer(ctx, parse_scene(BASE))

    def step(i: int) -> None:
        volume = ({"builtin": "sphere", "size": [6, 5, 6]} if i % 3 == 2
                  else {"path": files[i % 3]})
        changed = renderer.set_scene(parse_scene({**BASE, "volume": volume}))
        assert "volume" in changed
        renderer.render("pt", spp=1)

    try:
        check_no_growth(ctx, counted, step)
    finally:
        renderer.release()
    assert_all_released(ctx, counted)
