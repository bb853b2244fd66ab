"""Shader sources: ``#include "lib/x.glsl"`` (each file once), defines, and compile errors
reported with the real file names and lines. The GPU layer reads no file: the render layer gives
it the function that returns a shader file's text by name (set_source_reader;
app/rendering/shader_files.py, installed when app/rendering is imported).

Every included file gets its own GLSL source-string number through ``#line``; a compile log's
``0(12)`` is translated back to ``lib/medium.glsl:12``.
"""
from __future__ import annotations

import re
from typing import Mapping

import moderngl

from radiance_probes.gl.sources import (ShaderError, set_source_reader, shader_source)  # noqa: F401 (re-exported)
from radiance_probes.gl.context import is_software
from radiance_probes.gl.dispatch_log import active_log
from radiance_probes.gl.textures import transfer_buffer_bindable

GLSL_VERSION = "#version 430 core"
_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$')




def _expand(name: str, files: list[str], seen: set[str], text: str | None = None) -> list[str]:
    if name in seen:
        return []
    seen.add(name)
    if text is None:
        text = shader_source(name)
    index = len(files)
    files.append(name)
    out = [f"#line 1 {index}"]
    for lineno, line in enumerate(text.splitlines(), start=1):
        m = _INCLUDE.match(line)
        if m:
            out.extend(_expand(m.group(1), files, seen))
            out.append(f"#line {lineno + 1} {index}")
        elif line.lstrip().startswith("#version"):
            out.append("")  # the loader writes the one #version line
        else:
            out.append(line)
    return out


def _define_lines(defines: Mapping[str, object] | None) -> list[str]:
    lines = []
    for key, value in (defines or {}).items():
        if isinstance(value, bool):
            value = int(value)
        lines.append(f"#define {key} {value}")
    return lines


def load_source(name: str, defines: Mapping[str, object] | None = None,
                text: str | None = None) -> tuple[str, list[str]]:
    """The full source of a main file with its includes, and the list of files by source number.

    With `text`, that text is the main file (tests use this) and `name` only labels it.
    """
    files: list[str] = []
    body = _expand(name, files, set(), text)
    return "\n".join([GLSL_VERSION, *_define_lines(defines), *body]) + "\n", files


def _translate(log: str, files: list[str]) -> str:
    def repl(m: re.Match) -> str:
        idx, line = int(m.group(1)), m.group(2)
        return f"{files[idx]}:{line}" if idx < len(files) else m.group(0)
    return re.sub(r"\b(\d+)[:(](\d+)\)?", repl, log)


def transfer_from_buffer(ctx: moderngl.Context) -> bool:
    """Whether compute passes read the transfer table from its storage buffer (lib/medium.glsl
    TRANSFER_FROM_BUFFER) rather than with texelFetch: measured faster on the H100 (raymarched
    frame 5 to 17%, path-traced sample 4 to 6%; bench/h100-transfer-buffer), slower on llvmpipe
    (raymarched frame about 50%, bake about 30%), so on a GPU only, and one with the buffer's
    binding. The same values either way."""
    return not is_software(ctx) and transfer_buffer_bindable(ctx)


def compute_defines(ctx: moderngl.Context) -> dict:
    """Defines every compute pass on this device gets (a caller's own defines win): the transfer
    table's source, and SHADER_CHECKS in a context with the checking build (app/gl/checks.py)."""
    from radiance_probes.gl.checks import SHADER_CHECKS_BINDING, checks_for
    defines = {"TRANSFER_FROM_BUFFER": 1} if transfer_from_buffer(ctx) else {}
    if checks_for(ctx) is not None:
        defines.update(SHADER_CHECKS=1, SHADER_CHECKS_BINDING=SHADER_CHECKS_BINDING)
    return defines


class ComputeProgram:
    """A compiled compute pass: moderngl's ComputeShader (uniforms by name, release) whose `run`
    is timed by the active DispatchLog, if any (app/gl/dispatch_log.py)."""

    def __init__(self, shader: moderngl.ComputeShader, name: str):
        self.shader = shader
        self.name = name

    def run(self, group_x: int = 1, group_y: int = 1, group_z: int = 1) -> None:
        log = active_log()
        if log is None:
            self.shader.run(group_x, group_y, group_z)
            return
        queries = log.begin(self.shader.ctx)
        self.shader.run(group_x, group_y, group_z)
        log.end(self.name, queries)

    def __contains__(self, key) -> bool:
        return key in self.shader

    def __getitem__(self, key):
        return self.shader[key]

    def __setitem__(self, key, value) -> None:
        self.shader[key] = value

    def get(self, key, default=None):
        return self.shader.get(key, default)

    def release(self) -> None:
        self.shader.release()


def compute_program(ctx: moderngl.Context, name: str,
                    defines: Mapping[str, object] | None = None,
                    text: str | None = None) -> ComputeProgram:
    source, files = load_source(name, {**compute_defines(ctx), **(defines or {})}, text)
    try:
        return ComputeProgram(ctx.compute_shader(source), name)
    except moderngl.Error as exc:
        raise ShaderError(f"{name} failed to compile:\n{_translate(str(exc), files)}") from None


def render_program(ctx: moderngl.Context, vertex: str, fragment: str,
                   defines: Mapping[str, object] | None = None) -> moderngl.Program:
    vs, vfiles = load_source(vertex, defines)
    fs, ffiles = load_source(fragment, defines)
    try:
        return ctx.program(vertex_shader=vs, fragment_shader=fs)
    except moderngl.Error as exc:
        raise ShaderError(f"{vertex}+{fragment} failed to compile:\n"
                          f"{_translate(str(exc), ffiles)}") from None


def set_uniforms(program, values: Mapping[str, object]) -> None:
    """Set the uniforms a program uses; ones the compiler optimised away are skipped."""
    for key, value in values.items():
        if key in program:
            member = program[key]
            if hasattr(value, "tolist"):
                value = value.tolist()
            if isinstance(value, (list, tuple)) and member.dimension == 1:
                # an array of scalars (samplers, floats): the compiler keeps elements up to the
                # last one the shader reads; one kept element is a scalar uniform
                length = member.array_length
                value = value[0] if length == 1 else value[:length]
            member.value = value
