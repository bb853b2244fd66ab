"""The README's benchmark tables, regenerated from the committed records (markdown on stdout).

    python scripts/readme_tables.py speed [--records bench/h100] [--previous bench/archive/h100-v10]
    python scripts/readme_tables.py interact [--records bench/h100-interact]

`speed`: time to each target rRMSE (bake included) for the path tracer and the best probe method,
with the previous run's pair beside it. `interact`: the replay at 1920x1080, 128^3 x 64 probes, the
raymarcher (or --method), per event warm / cold."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.bench import report as R  # noqa: E402

# issue 11's targets: 5% and 2% on every scene, bonsai's 2% and the foot's 1% within 500 ms
SPEED_ROWS = [("fuel", "fuel", (0.05, 0.02, 0.01)), ("hydrogen", "hydrogen", (0.05, 0.02, 0.01)),
              ("foot", "foot", (0.05, 0.02, 0.01)), ("bonsai", "bonsai", (0.05, 0.02, 0.01)),
              ("thick", "thick (albedo 0.99)", (0.05, 0.02, 0.01)),
              ("anisotropic", "anisotropic (g = 0.8)", (0.05, 0.02)),
              ("grey", "grey", (0.05, 0.02))]
EVENTS = {"orbit": "orbit (60 frames)", "tf_drag": "opacity drag", "sun_30deg": "sun 30 degrees",
          "density": "density x 1.3", "albedo": "albedo - 0.15"}


def _ms(ms: float) -> str:
    """Milliseconds to three significant digits (seconds from 1 s: "2.58 s")."""
    return f"{ms / 1000:.3g} s" if ms >= 1000 else f"{ms:.3g} ms"


def _times(ratio: float) -> str:
    return f"{ratio:.0f}x" if ratio >= 10 else f"{ratio:.2g}x"


def speed(records: str, previous: str | None) -> None:
    new = R.load(records)
    old = R.load(previous) if previous else None
    print("| scene | target | path tracer | best probe method | speed-up | previous stop |")
    print("| --- | --- | --- | --- | --- | --- |")
    for scene, label, targets in SPEED_ROWS:
        recs = R.main_records(new, scene)
        if not recs:
            continue
        before = R.main_records(old, scene) if old else []
        for t in targets:
            pt = R.time_to_error([r for r in recs if r["method"] == "pt"], t)
            pb = R.time_to_error([r for r in recs if r["method"] != "pt"], t)
            pt_cell = "not reached" if pt is None else f"{_ms(pt['total_ms'])} ({pt['spp']} spp)"
            if pb is None:
                best = min((r for r in recs if r["method"] != "pt"), key=lambda r: R.error_of(new, r))
                pb_cell = f"not reached (best {R.error_of(new, best) * 100:.2f}%)"
            else:
                step = pb.get("raymarch_step", 0.5) if pb["method"] == "raymarch" else 0.5
                pb_cell = (f"{_ms(pb['total_ms'])} ({pb['method']}, {pb['probe_grid']}^3 x "
                           f"{pb['probe_samples']}, {pb['spp']} fr"
                           + (f", step {step:g}" if step != 0.5 else "")
                           + (f", gather {pb['gather_event']}" if R.gathered(pb) else "") + ")")
            up = "-" if pt is None or pb is None else _times(pt["total_ms"] / pb["total_ms"])
            prev = "-"
            if before:
                opt = R.time_to_error([r for r in before if r["method"] == "pt"], t)
                opb = R.time_to_error([r for r in before if r["method"] != "pt"], t)
                prev = (f"{'not reached' if opt is None else _ms(opt['total_ms'])} / "
                        f"{'not reached' if opb is None else _ms(opb['total_ms'])}")
                if opt is not None and opb is not None:
                    prev += f" ({_times(opt['total_ms'] / opb['total_ms'])})"
            print(f"| {label} | {t * 100:.0f}% | {pt_cell} | {pb_cell} | {up} | {prev} |")


def interact(records: str, method: str, width: int, grid: int) -> None:
    data = R.load(records)
    recs = [r for r in data["records"] if r.get("mode") == "interact" and r["width"] == width
            and r["probe_grid"] == grid and r["method"] == method]

    def n(x):
        return "never" if x is None else f"{x:.0f}"

    def ms(x):
        return "never" if x is None else f"{x:.0f} ms"

    print("| scene, event | first frame | frame p50 / p99 (warm, cold) | to 5% | to 3% | converged "
          "| speed check |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for scene in sorted({r["scene"] for r in recs}, key=lambda s: (s != "bonsai", s)):
        for event, label in EVENTS.items():
            rows = [r for r in recs if r["scene"] == scene and r["event"] == event]
            if not rows:
                continue
            warm = next(r for r in rows if r.get("variant") in ("warm", None))
            cold = next((r for r in rows if r.get("variant") == "cold"), None)
            if cold is None:
                print(f"| {scene}, {label} | {ms(warm['first_frame_ms'])} "
                      f"({ms(warm['first_frame_wall_ms'])}) | {warm['frame_ms_p50']:.1f} / "
                      f"{warm['frame_ms_p99']:.1f} ms | {ms(warm['ms_to_5pct'])} | "
                      f"{ms(warm['ms_to_3pct'])} | {warm['final_rrmse'] * 100:.2f}% | "
                      f"{warm['speed_check_ms']:.2f} ms |")
                continue
            both = lambda k: f"{n(warm[k])} / {n(cold[k])} ms"  # noqa: E731
            print(f"| {scene}, {label} | {both('first_frame_ms')} | {warm['frame_ms_p50']:.1f} / "
                  f"{warm['frame_ms_p99']:.1f}, {cold['frame_ms_p99']:.1f} ms | "
                  f"{both('ms_to_5pct')} ({both('wall_ms_to_5pct')}) | "
                  f"{both('ms_to_3pct')} ({both('wall_ms_to_3pct')}) | "
                  f"{warm['final_rrmse'] * 100:.2f}% | {warm['speed_check_ms']:.2f} / "
                  f"{cold['speed_check_ms']:.2f} ms |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("table", choices=("speed", "interact"))
    parser.add_argument("--records", help="the run's folder (default bench/h100, bench/h100-interact)")
    parser.add_argument("--previous", default="bench/archive/h100-v10", help="speed: the run to compare with")
    parser.add_argument("--method", default="raymarch", help="interact: the method's rows")
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--grid", type=int, default=128)
    args = parser.parse_args()
    if args.table == "speed":
        speed(args.records or "bench/h100", args.previous or None)
    else:
        interact(args.records or "bench/h100-interact", args.method, args.width, args.grid)


if __name__ == "__main__":
    main()
