"""The shaders' files (glsl/): the one place that reads them. The GPU layer (app/gl/shaders.py)
loads no file; importing app/rendering gives it `read_shader`, which returns a file's text by its
name under glsl/ (`"pathtrace.comp"`, `"lib/medium.glsl"`), and app/gl/checks.py reads the
checking build's site table through it too. An import-linter contract keeps the GPU layer off
app/paths.py (pyproject.toml)."""
from __future__ import annotations

from radiance_probes.gl.sources import ShaderError, set_source_reader
from radiance_probes.paths import GLSL_DIR


def read_shader(name: str) -> str:
    """The text of glsl/NAME, or ShaderError naming the file and the folder looked in."""
    path = GLSL_DIR / name
    if not path.is_file():
        raise ShaderError(f"shader include not found: {name} (looked in {GLSL_DIR})")
    return path.read_text()


def install() -> None:
    """Gives the GPU layer this reader (app/rendering/__init__.py calls it on import)."""
    set_source_reader(read_shader)
