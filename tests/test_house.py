"""The house rules, checked from the source: no import cycles in `radiance_probes` (the `app/` folder) (lazy imports inside
functions count too: a cycle is a cycle whenever it closes), and no behaviour switched by
environment variables other than the ones the README names as test shortcuts."""
from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
APP = ROOT / "app"

# Cycles that are known and owned elsewhere; each entry is the cycle's modules, sorted.
ALLOWED_CYCLES = {
}
# Environment variables the code may read, each named in the README as a shortcut for tests.
ALLOWED_ENV = {"RP_GL_BACKEND"}


def module_name(path: Path) -> str:
    """The installed name: the `app/` folder is the package `radiance_probes`."""
    parts = ["radiance_probes", *path.relative_to(APP).with_suffix("").parts]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in APP.rglob("*.py")}


def imports_of(name: str, path: Path, known: set[str]) -> set[str]:
    """The app modules `name` imports anywhere in its file (top level or inside functions)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                prefix = ".".join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module or ""
            # `from pkg import mod` imports the module pkg.mod; `from mod import name` imports mod.
            targets = [f"{prefix}.{a.name}" if f"{prefix}.{a.name}" in known else prefix
                       for a in node.names]
        for t in targets:
            while t and t not in known:
                t = t.rpartition(".")[0]
            if t and t != name:
                out.add(t)
    return out


def import_graph() -> dict[str, set[str]]:
    mods = modules()
    known = set(mods)
    return {name: imports_of(name, path, known) for name, path in mods.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_graph_sees_imports():
    """The checker itself: it finds relative, absolute, lazy and `from pkg import module` imports."""
    graph = import_graph()
    assert "radiance_probes.scene.types" in graph["radiance_probes.io.volume"]
    assert "radiance_probes.frontend.render_files" in graph["radiance_probes.cli.main"]
    assert "radiance_probes.viewer.launch" in graph["radiance_probes.cli.main"]          # lazy, inside cmd_view
    assert "radiance_probes.frontend.render_files" in graph["radiance_probes.viewer.launch"]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycles():
    found = [tuple(c) for c in cycles(import_graph())]
    unexpected = [c for c in found if c not in ALLOWED_CYCLES]
    assert not unexpected, "import cycles: " + "; ".join(" <-> ".join(c) for c in unexpected)


def test_environment_switches_are_only_the_named_test_shortcuts():
    readme = (ROOT / "README.md").read_text()
    used = set()
    for path in APP.rglob("*.py"):
        used |= set(re.findall(r"\b(RP_[A-Z0-9_]+)\b", path.read_text()))
    assert used <= ALLOWED_ENV, f"environment switches not allowed: {sorted(used - ALLOWED_ENV)}"
    for name in ALLOWED_ENV:
        assert name in readme, f"{name} is read by the code but the README does not name it"


def test_each_numpy_twin_names_the_glsl_file_it_mirrors():
    """app/twins/NAME.py mirrors glsl/lib/NAME.glsl or glsl/NAME.comp, and says so first."""
    twins = sorted(p for p in (APP / "twins").glob("*.py") if p.name != "__init__.py")
    assert len(twins) >= 7
    for p in twins:
        glsl = [g for g in (ROOT / "glsl").rglob(f"{p.stem}.*") if g.suffix in (".glsl", ".comp")]
        assert len(glsl) == 1, f"{p.name}: no single GLSL file named {p.stem} ({glsl})"
        first = ast.get_docstring(ast.parse(p.read_text())).splitlines()[0]
        expected = f"NumPy twin of {glsl[0].relative_to(ROOT).as_posix()}"
        assert first.startswith(expected), f"{p.name}: docstring starts {first!r}, not {expected!r}"


def test_the_design_layout_names_every_module():
    """docs/design.md's "Where each part lives" names every module of app/ and radiance_probes/
    under its folder's entry, and names no module that does not exist."""
    design = (ROOT / "docs" / "design.md").read_text()
    section = design[design.index("## Where each part lives"):design.index("**Paths are resumable.**")]
    for path in sorted([*APP.rglob("*.py"), *(ROOT / "radiance_probes").rglob("*.py")]):
        if path.name == "__init__.py" and path.parent.name != "radiance_probes":
            continue
        folder = path.parent.relative_to(ROOT).as_posix()
        line = next((block for block in section.split("\n- ") if block.startswith(f"`{folder}/`")),
                    None)
        assert line is not None, f"docs/design.md's layout has no entry for {folder}/"
        assert f"`{path.name}`" in line, f"docs/design.md's layout entry for {folder}/ omits {path.name}"
    for name in re.findall(r"`(app/[\w/]+\.py)`", section):
        assert (ROOT / name).is_file(), f"docs/design.md's layout names {name}, which does not exist"


def test_no_front_end_touches_a_renderers_private_fields():
    """The viewer, movies, the bench and the API drive a frame through the Renderer's public API
    (lend, begin, add_samples, forget_probes, ...): no file outside app/rendering/ reads or
    assigns a Renderer's private attribute."""
    pattern = re.compile(r"\b(?:r|renderer|self\.renderer|session\.renderer|self\._renderer)"
                         r"\._[a-z][a-z0-9_]*")
    found = []
    for path in APP.rglob("*.py"):
        if path.relative_to(APP).parts[0] == "rendering":
            continue
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if pattern.search(line.split("#")[0]):
                found.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert not found, "\n".join(found)


def test_the_layers_hold():
    """pyproject.toml's import contracts (scene and IO, the twins and the GPU layer, the
    renderers, the front ends: no layer imports one above it), checked by import-linter."""
    import subprocess
    import sys
    lint = Path(sys.executable).parent / "lint-imports"
    out = subprocess.run([str(lint)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-2000:]
    assert "0 broken" in out.stdout and out.stdout.count(" KEPT") >= 4


def test_the_gpu_layer_reads_shader_files_through_the_render_layer():
    """app/gl/ opens no file: its shaders' text comes from the reader app/rendering/ installs
    (shader_files.py); without one, a compile names what is missing instead of reading a path."""
    import subprocess
    import sys
    for path in (APP / "gl").rglob("*.py"):
        text = path.read_text()
        for word in ("GLSL_DIR", "paths import", ".glsl\").read", "glsl\" /"):
            assert word not in text, f"{path.relative_to(ROOT)} reads a shader file ({word})"
    code = ("import radiance_probes.gl.shaders as s\n"
            "try:\n    s.load_source('pathtrace.comp')\nexcept s.ShaderError as e:\n"
            "    print('refused:', e)\n"
            "import radiance_probes.rendering\n"
            "print(len(s.load_source('pathtrace.comp')[0]) > 1000)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "refused: no shader source reader" in out.stdout and "True" in out.stdout


def test_no_front_end_sets_lab_options():
    """LabOptions (app/rendering/lab_options.py) are the bench's and the experiments' comparison
    switches, not for users: nothing in the package outside the renderers makes one (scripts/,
    lab/ and tests do)."""
    found = [f"{p.relative_to(ROOT)}:{i}" for p in APP.rglob("*.py")
             if p.relative_to(APP).parts[0] != "rendering"
             for i, line in enumerate(p.read_text().splitlines(), 1)
             if "LabOptions(" in line.split("#")[0]]
    assert not found, found


# The house's size rules (docs/design.md, "Where each part lives").
MAX_MODULES_A_FOLDER = 25
MAX_LINES_A_MODULE = 800
BENCH_BUDGET_BYTES = 7_000_000     # bench/: the records' JSON, reports and clock logs, no plots
CODE_SUFFIXES = {".py", ".patch", ".diff", ".sh", ".glsl", ".comp", ".ipynb"}


def test_no_folder_of_the_package_holds_more_than_25_modules():
    crowded = {}
    for folder in [APP, *(p for p in APP.rglob("*") if p.is_dir() and p.name != "__pycache__")]:
        modules = [p for p in folder.glob("*.py") if p.name != "__init__.py"]
        if len(modules) > MAX_MODULES_A_FOLDER:
            crowded[folder.relative_to(ROOT).as_posix()] = len(modules)
    assert not crowded, f"folders over {MAX_MODULES_A_FOLDER} modules: {crowded}"


def test_no_module_is_longer_than_800_lines():
    long = {p.relative_to(ROOT).as_posix(): n for p in APP.rglob("*.py")
            if (n := len(p.read_text().splitlines())) > MAX_LINES_A_MODULE}
    assert not long, f"modules over {MAX_LINES_A_MODULE} lines (split them by idea): {long}"


def _tracked(prefix: str) -> list[Path]:
    import subprocess
    out = subprocess.run(["git", "ls-files", "-z", prefix], cwd=ROOT, capture_output=True)
    if out.returncode != 0:      # not a git checkout (an unpacked archive): the files on disk
        return [p for p in (ROOT / prefix).rglob("*") if p.is_file()]
    return [ROOT / f for f in out.stdout.decode().split("\0") if f and (ROOT / f).is_file()]


def test_bench_records_stay_under_their_budget():
    """bench/ holds records, not plots or arrays: `bench --report-only` draws the plots again."""
    files = _tracked("bench")
    total = sum(p.stat().st_size for p in files)
    assert total <= BENCH_BUDGET_BYTES, (
        f"bench/ holds {total / 1e6:.1f} MB, over its {BENCH_BUDGET_BYTES / 1e6:.0f} MB budget: "
        "gzip large results.json, leave plots and images out, move superseded runs out "
        "(one line each in docs/experiments.md)")
    arrays = [p.relative_to(ROOT).as_posix() for p in files if p.suffix in (".npy", ".npz", ".exr")]
    assert not arrays, f"arrays committed in records: {arrays}"
    plots = [p.relative_to(ROOT).as_posix() for p in files if p.suffix == ".png"]
    assert not plots, f"plots committed in records (draw them with --report-only): {plots}"


def test_no_record_folder_holds_code():
    code = [p.relative_to(ROOT).as_posix() for p in _tracked("bench") if p.suffix in CODE_SUFFIXES]
    assert not code, f"code in bench/ (experiments live in lab/experiments): {code}"
