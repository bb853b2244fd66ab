"""The checking build of the compute shaders (glsl/lib/checks.glsl): bounds checks on buffer,
image and texel indices and caps on loops, each hit counted per site in a storage buffer.

A context gets the checking build by `enable_checks(ctx)` before its programs are compiled (or
for every context, by setting RADIANCE_PROBES_SHADER_CHECKS=1 in the environment): every compute
program compiled in it then defines SHADER_CHECKS (app/gl/shaders.py compute_defines), and the
hits buffer stays bound at SHADER_CHECKS_BINDING. `checks_for(ctx).hits()` reads the counts by
site name; tests/test_battery.py requires them to be 0 over the stress battery.
"""
from __future__ import annotations

import os
import re

import moderngl
import numpy as np

from radiance_probes.gl.sources import shader_source

SHADER_CHECKS_BINDING = 9   # a storage binding no other pass uses (GL 4.3 promises 0-7; the
                            # checking build runs where there are more: llvmpipe 80, NVIDIA 96)
ENVIRONMENT_VARIABLE = "RADIANCE_PROBES_SHADER_CHECKS"
_SITE = re.compile(r"^#define CHECK_SITE_(\w+) (\d+)", re.M)


def check_sites() -> tuple[dict[int, str], int]:
    """Site number -> name (lower case) as glsl/lib/checks.glsl defines them, and the count (the
    file read through the render layer's reader, as every shader file is: shaders.py)."""
    found = _SITE.findall(shader_source("lib/checks.glsl"))
    count = next(int(n) for name, n in found if name == "COUNT")
    return {int(n): name.lower() for name, n in found if name != "COUNT"}, count


class ShaderChecks:
    """The hits buffer of one context's checking build."""

    def __init__(self, ctx: moderngl.Context):
        if int(ctx.info.get("GL_MAX_SHADER_STORAGE_BUFFER_BINDINGS", 0)) <= SHADER_CHECKS_BINDING:
            raise RuntimeError(f"the checking build needs storage binding {SHADER_CHECKS_BINDING}; "
                               f"this device has "
                               f"{ctx.info.get('GL_MAX_SHADER_STORAGE_BUFFER_BINDINGS')}")
        self.ctx = ctx
        self.sites, self.count = check_sites()
        self.buffer = ctx.buffer(reserve=4 * self.count)
        self.reset()

    def bind(self) -> None:
        self.buffer.bind_to_storage_buffer(SHADER_CHECKS_BINDING)

    def reset(self) -> None:
        self.buffer.write(bytes(4 * self.count))
        self.bind()

    def hits(self) -> dict[str, int]:
        """Hits per site since the last reset (only sites with hits)."""
        self.ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT)
        counts = np.frombuffer(self.buffer.read(), np.uint32)
        return {self.sites.get(i, f"site {i}"): int(c) for i, c in enumerate(counts) if c}

    def release(self) -> None:
        self.buffer.release()


_CHECKS: dict[int, ShaderChecks] = {}


def enable_checks(ctx: moderngl.Context) -> ShaderChecks:
    """The checking build for every compute program compiled in `ctx` from now on."""
    key = id(ctx.mglo)
    if key not in _CHECKS:
        _CHECKS[key] = ShaderChecks(ctx)
    return _CHECKS[key]


def checks_for(ctx: moderngl.Context) -> ShaderChecks | None:
    """The context's checking build, made on first use when the environment asks for it."""
    key = id(ctx.mglo)
    if key not in _CHECKS and os.environ.get(ENVIRONMENT_VARIABLE, "") not in ("", "0"):
        return enable_checks(ctx)
    return _CHECKS.get(key)


def disable_checks(ctx: moderngl.Context) -> None:
    """Forgets the context's checking build (programs compiled with it keep it)."""
    checks = _CHECKS.pop(id(ctx.mglo), None)
    if checks is not None:
        checks.release()
