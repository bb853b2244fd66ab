"""Where the shaders and assets are: beside the package in a checkout, inside it in a wheel."""
from __future__ import annotations

from pathlib import Path

_PKG = Path(__file__).resolve().parent


def _find(name: str) -> Path:
    for candidate in (_PKG / name, _PKG.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"cannot find the '{name}' folder next to or inside {_PKG}")


GLSL_DIR = _find("glsl")
ASSETS_DIR = _find("assets")
