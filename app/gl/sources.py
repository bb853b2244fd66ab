"""Where the GPU layer gets shader files' text: a function the render layer gives it
(app/rendering/shader_files.py, installed when app/rendering is imported). The GPU layer itself
reads no file (an import-linter contract keeps it off app/paths.py)."""
from __future__ import annotations

from typing import Callable


class ShaderError(RuntimeError):
    """A shader failed to compile or link, or a file it includes was not found; the message names
    the files and lines."""


# The text of a shader file by its name ("pathtrace.comp", "lib/medium.glsl"): given by the render
# layer (set_source_reader), None until then.
_read_source: Callable[[str], str] | None = None


def set_source_reader(read: Callable[[str], str]) -> None:
    """The function shader files are read with from now on."""
    global _read_source
    _read_source = read


def shader_source(name: str) -> str:
    """A shader file's text, through the reader the render layer gave."""
    if _read_source is None:
        raise ShaderError(f"no shader source reader for {name}: import radiance_probes.rendering, "
                          "which gives the GPU layer its files (rendering/shader_files.py)")
    return _read_source(name)
