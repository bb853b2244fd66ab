"""Shared fixtures: one headless OpenGL 4.3 context (Mesa llvmpipe through EGL in CI)."""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DATASETS = ROOT.parent / "shared" / "datasets"


@pytest.fixture(scope="session")
def ctx():
    from app.gl.context import create_headless_context
    context = create_headless_context()
    yield context
    context.release()


def dataset(name: str) -> Path:
    """A file of ../shared/datasets; tests that need one skip with the reason when it is absent."""
    p = DATASETS / name
    if not p.is_file():
        pytest.skip(f"dataset {p} is not present (../shared/datasets is optional)")
    return p
