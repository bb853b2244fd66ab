"""Shared fixtures: one headless OpenGL 4.3 context (Mesa llvmpipe through EGL in CI); and every
scene a test parses successfully is checked against the scene file's JSON Schema when the session
ends (docs/scene.schema.json: what the loader takes, an editor must not flag)."""
from __future__ import annotations

import copy
import json
import os
import shutil
from pathlib import Path

import pytest

import radiance_probes.io.scene_file as _scene_module

ROOT = Path(__file__).resolve().parents[1]
DATASETS = ROOT.parent / "shared" / "datasets"

# ---- every scene the tests parse, for the schema check at the session's end ----------------------
# Installed before any test module imports app.scene's parse_scene by name, so every caller (the
# loader, the CLI's options, the viewer's files, the bench) goes through it.
PARSED_SCENES: dict[str, object] = {}
_parse_scene = _scene_module.parse_scene


def _recording_parse_scene(data, base_dir=None):
    scene = _parse_scene(data, base_dir)
    try:
        text = json.dumps(data, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError):   # not JSON data (a test of Python-only input): no file has it
        return scene
    PARSED_SCENES.setdefault(text, copy.deepcopy(json.loads(text)))
    return scene


_scene_module.parse_scene = _recording_parse_scene


def pytest_sessionfinish(session, exitstatus):
    """Fails the run when a scene the loader accepted does not validate against the schema."""
    if not PARSED_SCENES:
        return
    try:
        import jsonschema
    except ImportError:   # the test extras are not installed: tests/test_scene_schema.py says so
        return
    from radiance_probes.io.scene_schema import scene_schema
    validator = jsonschema.Draft202012Validator(scene_schema())
    bad = []
    for data in PARSED_SCENES.values():
        error = jsonschema.exceptions.best_match(validator.iter_errors(data))
        if error is not None:
            bad.append(f"{json.dumps(data)[:300]}: {error.message} at "
                       f"{'.'.join(str(p) for p in error.absolute_path) or 'the top'}")
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        reporter.write_line("")
    if bad:
        if reporter is not None:
            reporter.write_line(f"{len(bad)} of {len(PARSED_SCENES)} scenes the loader accepted "
                                "do not validate against the scene schema:", red=True)
            for line in bad[:20]:
                reporter.write_line(f"  {line}", red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
    elif reporter is not None:
        reporter.write_line(f"scene schema: the {len(PARSED_SCENES)} scenes the tests parsed all "
                            "validate")


_SESSION_CONTEXT: list = []   # the session's context, once a test has asked for it


@pytest.fixture(scope="session")
def display():
    """One private X server for the session's real-window viewer runs (test_viewer,
    test_viewer_keep, test_slice_view)."""
    if shutil.which("Xvfb") is None and not os.path.exists("/usr/bin/Xvfb"):
        pytest.skip("Xvfb is not installed (scripts/setup.sh installs it)")
    from radiance_probes.viewer.xvfb import Xvfb
    with Xvfb(1280, 800) as name:
        yield name


@pytest.fixture(scope="session")
def ctx():
    import radiance_probes.rendering  # noqa: F401 (gives the GPU layer its shader files)
    from radiance_probes.gl.context import create_headless_context
    context = create_headless_context()
    _SESSION_CONTEXT.append(context)
    yield context
    _SESSION_CONTEXT.clear()
    context.release()


@pytest.fixture(scope="module")
def _checked():
    """A context of the module's own with the checking build (app/gl/checks.py) and its counts."""
    from radiance_probes.gl.checks import enable_checks
    from radiance_probes.gl.context import create_headless_context
    context = create_headless_context()
    checks = enable_checks(context)
    yield context, checks
    context.release()


@pytest.fixture
def checked_ctx(_checked):
    """(context, checks) of the checking build (programs cached per context elsewhere in the
    suite were compiled without it), current for the test (each test starts with the session's
    context current)."""
    _checked[0].__enter__()
    return _checked


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
