"""Which code in the walk shader costs the bake its speed (issue 42 item 7)? Builds copies of the
current tree with one piece of GLSL switched off by a text edit each, then times the same bake on
each with bake_bisect.py (the walks do the same steps in every copy; only the code differs):
    python lab/experiments/bake_variants.py OUT.json WORKDIR
  head        the tree as it is
  no-corr     the walks' sun-correction reservoir (lib/integrator.glsl) never runs
  no-clip     the crop/clip test (lib/clip_region.glsl, lib/medium.glsl) is constant 'keep'
  no-both     both
Each copy is a timing probe, not a renderer to use: no-corr loses the correction's unbiasedness,
no-clip ignores crops."""
import json
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
EDITS = {
    "no-corr": [("glsl/lib/integrator.glsl", "if (walk_sun_correction > 0.0) {", "if (false) {")],
    "no-clip": [("glsl/lib/clip_region.glsl", "clip_region_on == 0", "true"),
                ("glsl/lib/medium.glsl", "clip_region_on == 0", "true")],
}
EDITS["no-both"] = EDITS["no-corr"] + EDITS["no-clip"]
EDITS["one-fetch"] = [("glsl/lib/tracking.glsl", """    m = cell_majorant(w);                 // the cell holding the start (clamped into the grid)
    if (cell_walk_cross(w, t))
        m = cell_majorant(w);
    else if (!(t_end - t > SLIVER_ROUNDING * max(abs(t_end), 1.0)))
        return false;""", """    ivec3 start = w.cell;
    bool inside = cell_walk_cross(w, t);
    if (!inside && !(t_end - t > SLIVER_ROUNDING * max(abs(t_end), 1.0)))
        return false;
    m = texelFetch(majorant_grid, inside ? w.cell : start, 0).r;""")]


def edited_tree(work: Path, name: str, edits) -> Path:
    """work/name: a copy of this tree's app/, glsl/ and assets/ with each (path, old, new) text
    edit made (old must be there), beside a link work/shared to ../shared (the datasets)."""
    root = work / name
    if root.exists():
        shutil.rmtree(root)
    for part in ("app", "glsl", "assets"):
        shutil.copytree(ROOT / part, root / part)
    for path, old, new in edits:
        f = root / path
        text = f.read_text()
        if old not in text:
            raise SystemExit(f"{name}: '{old}' not in {path}")
        f.write_text(text.replace(old, new))
    (work / "shared").unlink(missing_ok=True)
    (work / "shared").symlink_to((ROOT / ".." / "shared").resolve())
    return root


def child_rows(code: str, name: str, *args: str) -> list[dict]:
    """Runs `code` in a fresh Python with `args` and returns the JSON of each line it printed as
    "RESULT {...}", with a row {"root": name, "error": ...} added where it printed none or failed
    (the edited copies' experiments: hybrid_raymarch_variants.py, hybrid_raymarch_costs.py)."""
    p = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True)
    rows = [json.loads(x[7:]) for x in p.stdout.splitlines() if x.startswith("RESULT ")]
    if not rows or p.returncode:
        rows.append({"root": name, "error": p.stderr[-1500:]})
    return rows


def keep_rows(out: Path, rows: list, got: list[dict]) -> None:
    """Prints a child's rows (child_rows) as they come, adds them to `rows` and writes every row
    so far to `out` (a run cut short keeps what it had)."""
    for g in got:
        print(json.dumps(g), flush=True)
    rows += got
    out.write_text(json.dumps(rows, indent=1))


def main() -> None:
    out, work = sys.argv[1], Path(sys.argv[2])
    names = sys.argv[3].split(",") if len(sys.argv) > 3 else ("head", *EDITS)
    roots = [str(edited_tree(work, name, EDITS.get(name, []))) for name in names]
    subprocess.run([sys.executable, str(ROOT / "lab/experiments/bake_bisect.py"), out, *roots],
                   check=True)


if __name__ == "__main__":
    main()
