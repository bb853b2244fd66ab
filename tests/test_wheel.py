"""The product is what a user installs: the wheel, built from this checkout and installed alone in
a clean virtual environment outside it, holds one top-level package (`radiance_probes`, no `app`),
its shaders and scenes, and renders the built-in scene and a NumPy array, from a folder that has an
`app` package of its own. The console script and `python -m radiance_probes` answer."""
from __future__ import annotations

import ast
import os
import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

RENDER = """
import numpy as np, radiance_probes as rp
print("from", rp.__file__)
a = rp.render(method="raymarch", width=24, height=16, spp=1)
b = rp.render(np.random.default_rng(0).random((12, 12, 12)), method="raymarch", width=16,
              height=16, spp=1)
assert a.shape == (16, 24, 3) and b.shape == (16, 16, 3), (a.shape, b.shape)
assert np.isfinite(np.asarray(a)).all() and np.asarray(a).max() > 0
print("rendered", a.shape, b.shape)
"""


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out),
                    str(ROOT)], check=True, capture_output=True, text=True, timeout=600)
    (found,) = out.glob("radiance_probes-*.whl")
    return found


def test_the_wheel_holds_one_package_with_its_shaders_and_scenes(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"radiance_probes"}
    for needed in ("radiance_probes/__init__.py", "radiance_probes/twins/sh.py",
                   "radiance_probes/glsl/pathtrace.comp", "radiance_probes/glsl/lib/medium.glsl",
                   "radiance_probes/assets/scenes/bonsai.json", "radiance_probes/assets/colormaps.json"):
        assert needed in names, needed
    # every Python package of the source tree is in it (discovered, not listed)
    for init in (ROOT / "app").rglob("__init__.py"):
        rel = init.relative_to(ROOT / "app").as_posix()
        assert f"radiance_probes/{rel}" in names, rel
    assert not [n for n in names if "__pycache__" in n]
    # the napari plugin's manifest, and the entry point napari finds it by
    assert "radiance_probes/napari_plugin/napari.yaml" in names
    entry = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
    points = zipfile.ZipFile(wheel).read(entry).decode()
    assert "[napari.manifest]" in points
    assert "radiance-probes = radiance_probes.napari_plugin:napari.yaml" in points


def test_no_module_imports_the_folder_name_app():
    """Inside the package everything is `radiance_probes` (or relative): an `import app...` would
    work in a checkout and fail in the wheel."""
    bad = []
    for path in (ROOT / "app").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level
                     else [])
            bad += [f"{path.relative_to(ROOT)}: {n}" for n in names if n.split(".")[0] == "app"]
    assert not bad, bad


def test_the_wheel_installed_alone_in_a_clean_venv_renders(wheel, tmp_path):
    env_dir = tmp_path / "venv"
    venv.EnvBuilder(with_pip=True).create(env_dir)
    python = env_dir / "bin" / "python"
    subprocess.run([str(python), "-m", "pip", "install", "-q", str(wheel)], check=True,
                   capture_output=True, text=True, timeout=900)
    user = tmp_path / "users_project"           # a folder with an `app` package of its own
    (user / "app").mkdir(parents=True)
    (user / "app" / "__init__.py").write_text("raise ImportError('the user app was imported')\n")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "DISPLAY")}
    run = subprocess.run([str(python), "-c", RENDER], cwd=user, env=env, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    assert str(env_dir) in run.stdout and "rendered (16, 24, 3) (16, 16, 3)" in run.stdout
    for cmd in ([str(env_dir / "bin" / "radiance-probes"), "--help"],
                [str(python), "-m", "radiance_probes", "--help"]):
        out = subprocess.run(cmd, cwd=user, env=env, capture_output=True, text=True, timeout=120)
        assert out.returncode == 0 and "usage: radiance-probes" in out.stdout, out.stderr[-2000:]
