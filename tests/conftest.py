"""Shared fixtures: one headless OpenGL 4.3 context (Mesa llvmpipe through EGL in CI)."""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DATASETS = ROOT.parent / "shared" / "datasets"


_SESSION_CONTEXT: list = []   # the session's context, once a test has asked for it


@pytest.fixture(scope="session")
def ctx():
    from app.gl.context import create_headless_context
    context = create_headless_context()
    _SESSION_CONTEXT.append(context)
    yield context
    _SESSION_CONTEXT.clear()
    context.release()


def _make_session_context_current() -> None:
    """Tests that run the CLI or the benchmark in-process create a context of their own, which
    stays current after they end. The session context's objects, among them the programs cached
    per context (the majorant grid's build pass), then belong to a context that is not current:
    the majorant grid came out as stale memory (0 everywhere) after tests/test_bench.py and
    tests/test_cli_errors.py, and an order-0 `probes` image lost pixels in test_probe_layout.py.
    So every module and every test starts with the session context current again."""
    if _SESSION_CONTEXT:
        _SESSION_CONTEXT[0].__enter__()


@pytest.fixture(scope="module", autouse=True)
def _session_context_current_for_the_module():
    _make_session_context_current()   # before the module's own fixtures build anything
    yield


@pytest.fixture(autouse=True)
def _session_context_current_for_the_test():
    _make_session_context_current()
    yield


def dataset(name: str) -> Path:
    """A file of ../shared/datasets; tests that need one skip with the reason when it is absent."""
    p = DATASETS / name
    if not p.is_file():
        pytest.skip(f"dataset {p} is not present (../shared/datasets is optional)")
    return p
