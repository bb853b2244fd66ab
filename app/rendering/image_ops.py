"""Zeroing and copying RGBA32F images on the GPU, each device its faster way: on a GPU compute
passes (glsl/image_copy.comp), on a software rasteriser a framebuffer clear or blit.

Measured with lab/experiments/clear_cost.py (docs/experiments.md): on the H200 a framebuffer
clear took 2.36 ms of GPU time at 3840x2160 (0.59 ms at 1920x1080) and a blit 2.63 ms (0.66),
against 0.04 and 0.06 ms (0.014 and 0.021) as compute passes; the viewer restarts its
accumulations after every bake slice and camera move, and the clear was the 2.4 ms a frame of
untimed GPU wait in the 4K orbit's frames. On llvmpipe the compute passes are the slower: 9.8
against 4.7 ms to clear and 12.0 against 2.6 ms to copy at 1920x1080."""
from __future__ import annotations

import weakref

import moderngl

from radiance_probes.gl.context import is_software
from radiance_probes.gl.shaders import ComputeProgram, compute_program

GROUP_SIDE = 16
SOURCE_UNIT, TARGET_UNIT = 0, 1   # image units (glsl/image_copy.comp's bindings)

# ctx -> {"clear": pass, "copy": pass}, compiled at first use
_programs: "weakref.WeakKeyDictionary[moderngl.Context, dict[str, ComputeProgram]]" = \
    weakref.WeakKeyDictionary()


def uses_compute(ctx: moderngl.Context, compute: bool | None = None) -> bool:
    """Whether images are cleared and copied with compute passes: `compute` where given (a
    caller forcing the way), else this device's way (see the module's text)."""
    return (not is_software(ctx)) if compute is None else compute


def _pass(ctx: moderngl.Context, kind: str) -> ComputeProgram:
    programs = _programs.setdefault(ctx, {})
    if kind not in programs:
        programs[kind] = compute_program(ctx, "image_copy.comp",
                                         {"CLEAR": 1} if kind == "clear" else None)
    return programs[kind]


def _run(ctx: moderngl.Context, program: ComputeProgram, size: tuple[int, int]) -> None:
    # earlier passes' image stores and reads of the target are done before it is written, and
    # what reads it next (image loads, texture fetches, blits, read-backs) sees the new texels
    ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)
    program.run((size[0] + GROUP_SIDE - 1) // GROUP_SIDE, (size[1] + GROUP_SIDE - 1) // GROUP_SIDE)
    ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)


def _check_rgba32f(texture: moderngl.Texture, what: str) -> None:
    if texture.components != 4 or texture.dtype != "f4":
        raise ValueError(f"{what}: an RGBA32F texture expected, got {texture.components} "
                         f"components of {texture.dtype}")


def clear_image(texture: moderngl.Texture, compute: bool | None = None) -> None:
    """Zeroes an RGBA32F texture (`compute`: force the way; None: this device's)."""
    ctx = texture.ctx
    _check_rgba32f(texture, "clear_image")
    if uses_compute(ctx, compute):
        texture.bind_to_image(TARGET_UNIT, read=False, write=True)
        _run(ctx, _pass(ctx, "clear"), texture.size)
        return
    frame = ctx.framebuffer(color_attachments=[texture])
    frame.clear(0.0, 0.0, 0.0, 0.0)
    frame.release()


def copy_image(source: moderngl.Texture, target: moderngl.Texture,
               compute: bool | None = None) -> None:
    """Copies RGBA32F `source` into `target` of its size, texel for texel (`compute`: force the
    way; None: this device's)."""
    ctx = source.ctx
    _check_rgba32f(source, "copy_image source")
    _check_rgba32f(target, "copy_image target")
    if source.size != target.size:
        raise ValueError(f"copy_image: source {source.size[0]}x{source.size[1]} and target "
                         f"{target.size[0]}x{target.size[1]} differ in size")
    if uses_compute(ctx, compute):
        source.bind_to_image(SOURCE_UNIT, read=True, write=False)
        target.bind_to_image(TARGET_UNIT, read=False, write=True)
        _run(ctx, _pass(ctx, "copy"), source.size)
        return
    ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)   # the passes wrote `source` through image stores
    # framebuffer to framebuffer (a blit keeps RGBA32F; a copy into a texture went through 8 bits
    # a channel)
    frames = [ctx.framebuffer(color_attachments=[t]) for t in (target, source)]
    ctx.copy_framebuffer(*frames)
    for frame in frames:
        frame.release()
