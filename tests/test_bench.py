"""The benchmark's metrics against known values, and one tiny end-to-end run on llvmpipe that must
write every required field (the benchmark itself is never a timed test)."""
import json

import numpy as np
import pytest

from radiance_probes.bench.config import BenchConfig
from radiance_probes.rendering.metrics import (corrected_floor, corrected_rrmse, flip,
                                               reference_noise, rrmse)
from radiance_probes.bench.report import pareto, time_to_error, write_report

REQUIRED = ("scene", "method", "probe_grid", "probe_samples", "spp", "bake_ms", "frame_ms",
            "total_ms", "rrmse", "flip", "gpu_bytes", "device")


def test_rrmse_known_values():
    ref = np.ones((4, 4, 3))
    assert rrmse(ref, ref) == 0.0
    assert rrmse(ref * 1.1, ref) == pytest.approx(0.1)
    with pytest.raises(ValueError, match="black"):
        rrmse(ref, np.zeros_like(ref))
    with pytest.raises(ValueError, match="shape"):
        rrmse(ref[:2], ref)


def test_reference_noise_matches_the_mean_of_two_halves():
    rng = np.random.default_rng(1)
    truth = np.full((256, 256, 3), 2.0)
    sigma_half = 0.2   # per-pixel noise of each half
    a = truth + rng.normal(0, sigma_half, truth.shape)
    b = truth + rng.normal(0, sigma_half, truth.shape)
    measured = rrmse(0.5 * (a + b), truth)
    assert reference_noise(a, b) == pytest.approx(measured, rel=0.02)
    assert measured == pytest.approx(sigma_half / np.sqrt(2) / 2.0, rel=0.02)


@pytest.mark.parametrize("true_error", [0.006, 0.01, 0.02])
def test_corrected_error_recovers_a_known_error_below_the_reference_noise(true_error):
    """Synthetic images: a structured truth, an image with a known relative error, a reference
    made of two noisy halves whose noise (3.5%) is far above that error. The plain rRMSE sees
    mostly the reference's noise; the corrected one recovers the true error within a few percent
    of itself once it is above the stated floor, and stays below the floor when the error is 0."""
    rng = np.random.default_rng(7)
    h = w = 512
    yy, xx = np.mgrid[0:h, 0:w] / 512.0
    truth = np.stack([1.0 + np.sin(6 * xx) * np.cos(4 * yy), 0.5 + xx, 0.8 + 0.3 * yy], -1)
    truth_rms = np.sqrt(np.mean(truth ** 2))
    error = rng.normal(0.0, 1.0, truth.shape) * np.exp(-3 * xx)[..., None]   # uneven, any sign
    error *= true_error * truth_rms / np.sqrt(np.mean(error ** 2))
    image = truth + error
    sigma_half = 0.05 * truth_rms   # each half's noise; the mean of both has 0.05 / sqrt(2)
    a = truth + rng.normal(0, sigma_half, truth.shape)
    b = truth + rng.normal(0, sigma_half, truth.shape)
    reference = 0.5 * (a + b)
    noise = reference_noise(a, b)
    assert noise == pytest.approx(0.05 / np.sqrt(2), rel=0.02)
    measured = rrmse(image, reference)
    assert measured > 1.7 * true_error                     # the noise hides the error...
    floor = corrected_floor(noise, h * w)
    assert 0.002 < floor < true_error
    assert corrected_rrmse(measured, noise) == pytest.approx(true_error, rel=0.1)  # ...not this
    assert abs(corrected_rrmse(rrmse(truth, reference), noise)) < floor       # zero error
    assert corrected_rrmse(0.2, 0.0) == pytest.approx(0.2)                     # no noise: as is


def test_flip_zero_for_identical_and_grows_with_difference():
    rng = np.random.default_rng(2)
    ref = rng.uniform(0.1, 0.8, (32, 32, 3)).astype(np.float32)
    assert flip(ref, ref) == pytest.approx(0.0, abs=1e-6)
    assert flip(ref * 1.5, ref) > flip(ref * 1.1, ref) > 0.0


def test_pareto_and_time_to_error():
    recs = [{"total_ms": t, "rrmse": e, "error": e} for t, e in ((1, 0.5), (2, 0.6), (3, 0.1),
                                                                   (4, 0.2))]
    assert [r["total_ms"] for r in pareto(recs)] == [1, 3]
    assert time_to_error(recs, 0.3)["total_ms"] == 3
    assert time_to_error(recs, 0.05) is None


def test_errors_below_the_reference_floor_are_never_stated():
    """Errors are stated corrected for the reference's noise, and never below what the correction
    resolves (the floor, from the noise and the pixel count)."""
    from radiance_probes.rendering.metrics import corrected_floor
    from radiance_probes.bench.report import err, floor, main_records
    data = {"meta": {"config": {"width": 64, "height": 64}},
            "references": {"s": {"noise_rrmse": 0.02}},
            "records": [{"scene": "s", "method": "pt", "rrmse": 0.0201, "total_ms": 1.0},
                        {"scene": "s", "method": "pt", "rrmse": 0.05, "total_ms": 0.5},
                        {"scene": "s", "method": "pt", "rrmse": 0.03, "total_ms": 0.7,
                         "reference_noise": 0.0}]}
    lo = floor(data, "s")
    assert lo == pytest.approx(corrected_floor(0.02, 64 * 64)) and 0.002 < lo < 0.02
    low, high, own = main_records(data, "s")
    assert low["below_floor"] and low["error"] == pytest.approx(lo) and err(low) == f"<{lo:.4f}"
    expected = np.sqrt((0.05 ** 2 - 0.02 ** 2) / (1 - 0.02 ** 2))
    assert not high["below_floor"] and high["error"] == pytest.approx(expected)
    assert err(high) == f"{expected:.4f}"
    assert own["error"] == pytest.approx(0.03)   # measured against a noise-free reference


def test_tiny_benchmark_writes_every_field(ctx, tmp_path):
    from radiance_probes.bench.runner import run_bench
    config = BenchConfig(scenes=("anisotropic",), width=16, height=16, ref_spp=64,
                         ref_samples_per_pass=32, pt_spp=(1, 4), probe_grids=(2,),
                         probe_samples=(16,), large_grids=(), probe_frames=(1, 4),
                         raymarch_frames=(1,), showcase=(2, 16), raymarch_steps=(0.5, 1.0),
                         sweep_raymarch_steps=(0.5, 2.0), samples_per_dispatch=2,
                         flip_frames=(4,), image_frames=4, probe_layouts=("uniform", "extinction"),
                         probe_precision="rgba16f", sh_orders=(2, 3), gather_events=(2,),
                         gather_settings=((2, 16),), gather_frames=(2, 4),
                         speed_check_rays=1 << 10)
    path = run_bench(config, tmp_path, command="test")
    data = json.loads(path.read_text())
    records = data["records"]
    methods = {r["method"] for r in records}
    assert methods == {"pt", "probes", "probes-only", "raymarch"}
    for r in records:
        for key in REQUIRED:
            assert key in r, f"{key} missing from {r}"
        assert np.isfinite(r["rrmse"]) and r["rrmse"] > 0
        assert r["frame_ms"] >= 0 and r["total_ms"] >= r["bake_ms"]
        assert r["gpu_bytes"] >= 16 * 16 * 16
        assert r["speed_check_ms"] > 0   # the device's speed when the record was taken
        if r["method"] == "raymarch":   # every raymarched image pays for its light grid
            assert r["light_ms"] > 0 and r["bake_ms"] >= r["light_ms"]
        if r["method"] == "pt" or r["spp"] in config.flip_frames:
            assert r["flip"] is not None and 0.0 <= r["flip"] <= 1.0
        if r["method"] != "pt":
            assert r["probe_grid"] == 2 and r["probe_samples"] == 16
    # the sweep in the asked-for precision (--probe-precision), and the showcase setting's
    # variants: the other precision, a Hann window (g != 0), both raymarch stages
    precisions = [r.get("precision") for r in records if r["method"] != "pt"]
    assert precisions.count("rgba16f") > precisions.count("rgba32f") > 0
    assert any(r.get("sh_window") == "hann" for r in records)
    assert {r.get("stage") for r in records if r["method"] == "raymarch"} == {"compute", "fragment"}
    # the layouts at the same probe count (--probe-layouts)
    layouts = {r.get("probe_layout") for r in records if r["method"] != "pt"}
    assert layouts == {"uniform", "adaptive-extinction"}
    assert all("layout_ms" in r for r in records if r.get("probe_layout") == "adaptive-extinction")
    # the SH orders at the same setting (--sh-orders): g = 0.8 with 16 walks bakes order 2 ("auto"
    # keeps higher bands for 128 walks or more); order 3 runs as a variant, out of the main tables
    orders = {(r["sh_order"], bool(r.get("sh_order_variant"))) for r in records if r["method"] != "pt"}
    assert orders == {(2, False), (3, True)}
    from radiance_probes.bench.report import main_records
    main = main_records(data, "anisotropic")
    assert main and not any(r.get("sh_order_variant") for r in main)
    # the raymarch steps: the sweep's at every setting and variant (the main tables take them),
    # the showcase's own (1.0) only in its table
    steps = lambda recs: {r["raymarch_step"] for r in recs if r["method"] == "raymarch"}
    assert steps(main) == {0.5, 2.0}
    assert steps(r for r in records if r.get("sh_order_variant")) == {0.5, 2.0}
    assert steps(records) == {0.5, 1.0, 2.0}
    from radiance_probes.bench.report import label
    assert [label(r) for r in main if r.get("raymarch_step") == 2.0][0].endswith(", step 2")
    assert data["references"]["anisotropic"]["noise_rrmse"] > 0
    assert (tmp_path / "images" / "anisotropic_reference.png").is_file()
    report = write_report(path)
    text = report.read_text()
    assert "Time to reach an error" in text and (tmp_path / "error_vs_time.png").is_file()
    assert "Probe layouts at the same probe count" in text and "adaptive-extinction" in text
    assert "SH orders at the same probe setting" in text and "| anisotropic | 2^3 x 16 | 3 |" in text
    assert "The device's speed during the run" in text
    # the final gather: `probes` at event 2 at the gather setting, to its own frames, in the
    # main tables with its own label, kept out of the per-setting tables
    gathered = [r for r in records if r.get("gather_event", 1) > 1]
    assert {(r["method"], r["gather_event"], r["spp"]) for r in gathered} == {
        ("probes", 2, 2), ("probes", 2, 4)}
    assert all(r["precision"] == "rgba16f" and not r.get("sh_order_variant") for r in gathered)
    assert sum(1 for r in main if r.get("gather_event") == 2) == 2
    assert all(label(r).endswith(", gather 2") for r in gathered)
    assert "## Final gather" in text and "| 2^3 x 16 | 2 |" in text
    table1 = text.split("## Probe grid x samples per probe")[1].split("## ")[0]
    assert "gather" not in table1


def test_records_after_a_slow_speed_check_are_counted(tmp_path):
    """The report counts the records taken after a speed check slower than the scene's fastest
    by more than SPEED_CHECK_SLOWER (a shared or clocked-down GPU), and only those."""
    from radiance_probes.rendering.budgets.ceiling import SPEED_CHECK_SLOWER
    def rec(check):
        return {"scene": "s", "method": "pt", "rrmse": 0.1, "total_ms": 1.0, "spp": 1,
                "frame_ms": 1.0, "bake_ms": 0.0, "probe_grid": None, "probe_samples": None,
                "flip": None, "gpu_bytes": 0, "speed_check_ms": check}
    checks = [1.0, 1.1, SPEED_CHECK_SLOWER * 0.99, 2.5, 3.0]
    data = {"meta": {"device": "d", "command": "c", "config": {"width": 4, "height": 4}},
            "references": {"s": {"noise_rrmse": 0.0}}, "records": [rec(c) for c in checks]}
    path = tmp_path / "results.json"
    path.write_text(json.dumps(data))
    text = write_report(path).read_text()
    section = text.split("## The device's speed during the run")[1].split("## ")[0]
    assert "| s | 1.000 | 1.188 | 3.000 | 2 of 5 |" in section


def test_cost_mode_measures_each_variant_against_the_baseline(ctx, tmp_path):
    from radiance_probes.bench.cost import PROBE_VARIANTS
    from radiance_probes.bench.runner import run_bench
    config = BenchConfig(mode="cost", scenes=("anisotropic",), width=12,
                         height=12, ref_spp=32, ref_samples_per_pass=16, samples_per_dispatch=2,
                         cost_settings=((3, 16),), cost_probe_frames=2, cost_raymarch_frames=2,
                         cost_pt_spp=2, cost_auto_targets=(0.9,), auto_check_frames=(1, 2),
                         auto_pilot_side=16, auto_pilot_frames=8)
    first = run_bench(config, tmp_path / "a")
    # a second run reuses the first one's reference and its measured noise
    again = run_bench(config.scaled(reference_dir=str(tmp_path / "a")), tmp_path / "b")
    data = json.loads(again.read_text())
    assert data["references"]["anisotropic"]["loaded_from"].endswith("anisotropic.npy")
    assert (data["references"]["anisotropic"]["noise_rrmse"]
            == json.loads(first.read_text())["references"]["anisotropic"]["noise_rrmse"])
    probes = [r for r in data["records"] if r["method"] == "probes"]
    assert {r["variant"] for r in probes} >= {label for label, _ in PROBE_VARIANTS}
    by = {r["variant"]: r for r in probes}
    assert by["rgba16f"]["probe_bytes"] * 2 == by["baseline"]["probe_bytes"]
    assert by["fit visible"]["probe_grid_xyz"] != [3, 3, 3]   # the cloud is flatter than its box
    auto = [r for r in data["records"] if r.get("variant") == "auto 0.9"]
    assert [r["spp"] for r in auto] == [1, 2]        # checked after each of auto_check_frames
    assert all(r["auto_met"] == (r["rrmse"] <= 0.9) for r in auto)
    assert all(r["auto_pilot_side"] == 16 and r["auto_pilot_frames"] == 8 for r in auto)
    assert auto[1]["total_ms"] > auto[0]["total_ms"]
    # the image's total charges the whole search (its bakes included), not just the render
    assert auto[0]["bake_ms"] > 0 and auto[0]["auto_search_ms"] >= auto[0]["bake_ms"]
    assert auto[0]["total_ms"] >= auto[0]["auto_search_ms"] + auto[0]["render_ms"] - 1e-9
    text = write_report(again).read_text()
    assert "Cost that follows the scene" in text and "| baseline |" in text
    assert "| auto target |" in text


def test_bake_mode_profiles_the_bake(ctx, tmp_path):
    """The bake mode's records carry the profile fields, consistent with each other: the sections
    add up to the profiled bake, walks per second follow from the walk count and bake time, the
    counters counted every walk, and total_ms charges the bake and light grid to the image."""
    from radiance_probes.bench.runner import run_bench
    config = BenchConfig(mode="bake", scenes=("anisotropic",), width=12, height=12, ref_spp=32,
                         ref_samples_per_pass=16, samples_per_dispatch=2, raymarch_frames=(2,),
                         bake_settings=((3, 16), (2, 96)), bake_repeats=2, ceiling_rays=4096,
                         bake_variants=(("ray", 8, 0.0), ("grid", 8, 1.0)))
    path = run_bench(config, tmp_path)
    records = json.loads(path.read_text())["records"]
    assert [(r["probe_grid"], r["probe_samples"], r["walk_sun"], r["walk_adaptive"])
            for r in records] == [(3, 16, "ray", 0), (3, 16, "grid", 1.0), (2, 96, "ray", 0),
                                  (2, 96, "grid", 1.0)]
    for r in records:
        for key in ("bake_walk_ms", "bake_project_ms", "bake_other_ms", "walks_per_s",
                    "steps_per_walk", "ceiling_steps_per_s", "ceiling_fraction"):
            assert r[key] is not None and np.isfinite(r[key]) and r[key] >= 0, key
        assert r["mode"] == "bake" and r["method"] == "raymarch"
        assert r["walks"] == np.prod(r["probe_grid_xyz"]) * r["probe_samples"]
        if r["walk_adaptive"]:
            assert 0 < r["counted_walks"] <= r["walks"]
        else:
            assert r["counted_walks"] == r["walks"]
        sections = r["bake_walk_ms"] + r["bake_project_ms"] + r["bake_sun_ms"] + r["bake_other_ms"]
        assert sections == pytest.approx(r["bake_profiled_ms"], rel=1e-6)
        assert r["walks_per_s"] == pytest.approx(r["walks"] / (r["probe_bake_ms"] / 1e3))
        assert r["total_ms"] == pytest.approx(r["probe_bake_ms"] + r["light_ms"] + r["render_ms"])
        assert r["light_ms"] > 0   # the light grid's real time (it was 0: a stale attribute)
        assert r["steps_per_walk"] >= 1.0 and r["ceiling_fraction"] > 0
    text = write_report(path).read_text()
    assert "The probe bake" in text and "| current | 3^3 x 16" in text and "sun grid" in text


def test_a_runs_caveat_heads_its_report(tmp_path):
    """A run recorded with a known shortcoming says so at the top of its report."""
    data = {"meta": {"device": "d", "command": "c", "config": {"width": 4, "height": 4},
                     "caveat": "the light grid is charged once"},
            "references": {"s": {"noise_rrmse": 0.0}},
            "records": [{"scene": "s", "method": "pt", "rrmse": 0.1, "total_ms": 1.0, "spp": 1,
                         "frame_ms": 1.0, "bake_ms": 0.0, "probe_grid": None,
                         "probe_samples": None, "flip": None, "gpu_bytes": 0}]}
    path = tmp_path / "results.json"
    path.write_text(json.dumps(data))
    text = write_report(path).read_text()
    assert "**Caveat:** the light grid is charged once" in text.split("## ")[0]


def test_results_are_written_at_most_every_interval_and_all_at_the_end(tmp_path):
    """Writing results.json after every record left the GPU idle long enough to clock down in the
    middle of timed runs: records now reach the file at most every flush_every_s seconds, and all
    of them (with FLIP filled in) at close."""
    from radiance_probes.bench.runner import Results
    path = tmp_path / "results.json"
    results = Results(path, {"device": "test"})
    results.flush_every_s = 1e9
    image = np.full((8, 8, 3), 0.5, np.float32)
    results.add({"scene": "a", "n": 0}, image, image)        # the first record is written at once
    assert [r["n"] for r in json.loads(path.read_text())["records"]] == [0]
    for n in range(1, 5):
        results.add({"scene": "a", "n": n}, image, image * 1.1)
    assert [r["n"] for r in json.loads(path.read_text())["records"]] == [0]
    results.close()
    written = json.loads(path.read_text())["records"]
    assert [r["n"] for r in written] == [0, 1, 2, 3, 4]
    assert written[0]["flip"] == 0.0 and all(r["flip"] > 0 for r in written[1:])


@pytest.mark.parametrize("method", ["pt", "raymarch"])
def test_progressive_snapshots_are_the_images_read_between_dispatches(ctx, method):
    """The benchmark's timed runs copy each snapshot on the GPU and read them all afterwards; the
    images are the ones a read-back after each snapshot's dispatches gives."""
    from radiance_probes.bench.records import progressive
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.io.scene_file import parse_scene
    r = Renderer(ctx, parse_scene({"volume": {"builtin": "cloud", "size": [12, 10, 8]},
                                   "camera": {"eye": [0, 0.2, 1.3], "target": [0, 0, 0],
                                              "fov_y": 40.0, "width": 12, "height": 10},
                                   "probes": {"grid": [3, 3, 3], "samples": 16}}))
    r.bake()
    runs = list(progressive(r, method, (1, 3, 4), seed=5, per_dispatch=2))
    assert [n for n, *_ in runs] == [1, 3, 4]
    assert runs[-1][3] >= runs[0][3] > 0.0          # cumulative GPU ms
    r.begin(method, seed=5)
    for (n, image, *_), add in zip(runs, (1, 2, 1)):
        r.add_samples(add)
        assert r.samples == n
        np.testing.assert_array_equal(image, r.image())
    assert not np.array_equal(runs[0][1], runs[-1][1])
    r.release()


def test_gpu_clock_log_summarises_what_nvidia_smi_printed(tmp_path):
    """The run's clock log (app/bench/clock_log.py): nvidia-smi's samples summarised for the
    report, half of these below 90% of the maximum clock; nothing where nvidia-smi is absent."""
    import os
    import time
    from radiance_probes.bench.clock_log import ClockLog, report_lines
    fake = tmp_path / "nvidia-smi"
    fake.write_text("#!/bin/sh\nwhile true; do\n echo '2026/11/23 10:00:00.000, 990, 1980, 12'\n"
                    " echo '2026/11/23 10:00:00.500, 1980, 1980, 99'\n sleep 0.05\ndone\n")
    fake.chmod(0o755)
    log = ClockLog(tmp_path / "nvidia-smi.csv", executable=str(fake))
    assert log.start()
    time.sleep(0.3)
    clock = log.stop()
    assert clock["samples"] >= 2 and clock["sm_mhz_min"] == 990 and clock["sm_mhz_max"] == 1980
    assert clock["sm_mhz_limit"] == 1980 and abs(clock["below_fraction"] - 0.5) <= 1.0 / clock["samples"]
    line = report_lines({"gpu_clock": clock})[-1]
    assert "990 to 1980 MHz" in line and "of at most 1980" in line
    absent = ClockLog(tmp_path / "none.csv", executable=os.path.join(str(tmp_path), "missing"))
    assert not absent.start() and absent.stop() is None and report_lines({}) == []


def test_sh_orders_argument_names_what_is_wrong():
    import argparse
    from radiance_probes.cli.main import sh_orders_arg
    assert sh_orders_arg("2,3,4,3") == (2, 3, 4)
    for bad in ("", "5", "2,x", "-1"):
        with pytest.raises(argparse.ArgumentTypeError, match="SH orders 0 to 4"):
            sh_orders_arg(bad)


def test_auto_targets_argument_names_what_is_wrong():
    import argparse
    from radiance_probes.cli.main import auto_targets_arg
    assert auto_targets_arg("0.05,0.02,0.05") == (0.05, 0.02)
    for bad in ("", "0", "1.5", "0.05,x", "-0.1"):
        with pytest.raises(argparse.ArgumentTypeError, match=r"targets in \(0, 1\)"):
            auto_targets_arg(bad)


def test_archived_runs_load_and_report_as_the_plain_ones(tmp_path):
    """A superseded run's results.json.gz (archived so the checkout fits the GPU machine's
    transfer) reads as the same records, and its folder reports as the plain one's does."""
    import gzip

    from radiance_probes.bench.report import load, results_path
    data = {"meta": {"device": "test", "command": "x"}, "references": {},
            "records": [{"scene": "s", "method": "pt", "rrmse": 0.1, "total_ms": 1.0}]}
    plain, archived = tmp_path / "plain", tmp_path / "archived"
    plain.mkdir()
    archived.mkdir()
    (plain / "results.json").write_text(json.dumps(data))
    (archived / "results.json.gz").write_bytes(gzip.compress(json.dumps(data).encode()))
    assert results_path(plain).name == "results.json"
    assert results_path(archived).name == "results.json.gz"
    assert load(archived) == load(plain) == load(plain / "results.json") == data
    # a folder with both reads the plain file (a run written again after archiving)
    (archived / "results.json").write_text(json.dumps({**data, "records": []}))
    assert load(archived)["records"] == []
    assert results_path(tmp_path / "missing").name == "results.json"


def test_merged_runs_keep_every_runs_clock_log(tmp_path):
    """Runs of one device merged into one report: their records and references together, and
    their clock logs one after the other, summarised over all of them (a slow second run shows)."""
    from radiance_probes.bench.report import merge
    rows = {"a": ["2026/11/25 06:00:00.000, 1980, 1980, 90"] * 3,
            "b": ["2026/11/25 06:05:00.000, 405, 1980, 10", "2026/11/25 06:05:00.500, 1980, 1980, 95"]}
    paths = []
    for name, lines in rows.items():
        folder = tmp_path / name
        folder.mkdir()
        (folder / "nvidia-smi.csv").write_text("\n".join(lines) + "\n")
        data = {"meta": {"device": "gpu", "command": f"run {name}",
                         "gpu_clock": {"samples": len(lines)}},
                "references": {name: {"noise_rrmse": 0.01}},
                "records": [{"scene": name, "method": "pt", "rrmse": 0.1, "total_ms": 1.0}]}
        (folder / "results.json").write_text(json.dumps(data))
        paths.append(folder / "results.json")
    out = merge(paths, tmp_path / "merged" / "results.json")
    merged = json.loads(out.read_text())
    assert {r["scene"] for r in merged["records"]} == {"a", "b"}
    assert set(merged["references"]) == {"a", "b"}
    assert merged["meta"]["command"] == "run a ; run b"
    clock = merged["meta"]["gpu_clock"]
    assert clock["samples"] == 5 and clock["sm_mhz_min"] == 405 and clock["sm_mhz_max"] == 1980
    assert (tmp_path / "merged" / "nvidia-smi.csv").read_text().count("\n") == 5


def test_the_dependent_chain_marches_the_same_steps_as_the_ceiling(ctx):
    """The walk latency floor (DEPENDENT_CHAIN in glsl/ceiling_march.comp) reads the same sigma_t
    at the same points as the throughput ceiling; only the order of waiting differs."""
    from radiance_probes.rendering.budgets.ceiling import measure_ceiling
    from radiance_probes.rendering.renderer import Renderer
    from radiance_probes.io.scene_file import parse_scene
    r = Renderer(ctx, parse_scene({"volume": {"builtin": "cloud", "size": [16, 12, 14]},
                                   "density_scale": 50.0}))
    plain = measure_ceiling(r, rays=256, steps=32, repeats=1)
    chain = measure_ceiling(r, rays=256, steps=32, repeats=1, chain=True)
    assert plain["sigma_t_sum"] > 0 and chain["sigma_t_sum"] == plain["sigma_t_sum"]
    assert chain["steps"] == plain["steps"] == 256 * 32 and chain["ms"] > 0
    r.release()


def test_convergence_table_tells_a_floor_from_noise(tmp_path):
    """Synthetic runs: an unbiased method whose error falls as samples^-1/2 (slope -0.5), a
    biased one whose error levels off at a 3% floor (slope near 0), and one too short to judge.
    The report's convergence table gives each its slope and says which keeps falling; the plot
    is written."""
    from radiance_probes.bench.report import FLOOR_SLOPE, series, tail_slope
    base = {"scene": "s", "device": "test", "width": 64, "height": 64, "reference_noise": 0.0,
            "frame_ms": 1.0, "gpu_bytes": 0}
    records = []
    for spp in (1, 4, 16, 64, 256, 1024):
        records.append(dict(base, method="pt", spp=spp, bake_ms=0.0, total_ms=2.0 * spp,
                            rrmse=0.4 / spp ** 0.5, probe_grid=None, probe_samples=None))
        records.append(dict(base, method="probes", spp=spp, bake_ms=50.0, total_ms=50 + 0.5 * spp,
                            rrmse=(0.03 ** 2 + 0.3 ** 2 / spp) ** 0.5, probe_grid=32,
                            probe_samples=64, precision="rgba32f", sh_window="none"))
    for spp in (1, 4):
        records.append(dict(base, method="guided", spp=spp, bake_ms=5.0, total_ms=5 + 3.0 * spp,
                            rrmse=0.5 / spp ** 0.5, probe_grid=32, probe_samples=64,
                            precision="rgba32f", sh_window="none"))
    path = tmp_path / "results.json"
    path.write_text(json.dumps({"meta": {"device": "test", "config": {"width": 64, "height": 64}},
                                "references": {"s": {"spp": 1, "noise_rrmse": 0.0}},
                                "records": records}))
    from radiance_probes.bench.report import load, main_records
    runs = series(main_records(load(path), "s"))
    slopes = {k[0]: tail_slope(run) for k, run in runs.items()}
    assert slopes["pt"] == pytest.approx(-0.5, abs=1e-9)
    assert FLOOR_SLOPE < slopes["probes"] < 0           # 3.1% -> 3.0%: levelled off
    assert slopes["guided"] is None                      # 4x of samples: too short to say
    text = write_report(path).read_text()
    section = text.split("## Convergence")[1].split("## ")[0]
    assert "| s | pt | pt 1024 spp |" in section and "-0.50 | still falling |" in section
    assert "| s | probes | probes 32^3x64, 1024 fr |" in section
    assert "levelling off (a floor)" in section and "guided" not in section
    assert (tmp_path / "convergence.png").is_file()


def test_the_benchs_defaults_are_the_modules():
    """BenchConfig's speed_check_rays, auto_pilot_side and auto_pilot_frames default to
    ceiling.SPEED_CHECK_RAYS and auto_probes' PILOT_SIDE and PILOT_FRAMES (config.py writes the
    numbers out so that it imports no GL): the GPU presets measure what the records did."""
    from radiance_probes.rendering.budgets.ceiling import SPEED_CHECK_RAYS
    from radiance_probes.bench.config import PRESETS
    assert BenchConfig().speed_check_rays == SPEED_CHECK_RAYS
    assert PRESETS["gpu"].speed_check_rays == PRESETS["interact"].speed_check_rays == SPEED_CHECK_RAYS
    assert PRESETS["interact-quick"].speed_check_rays < SPEED_CHECK_RAYS
    from radiance_probes.rendering.probes.auto import PILOT_FRAMES, PILOT_SIDE
    assert (BenchConfig().auto_pilot_side, BenchConfig().auto_pilot_frames) == (PILOT_SIDE,
                                                                               PILOT_FRAMES)


class _WarmUpRenderer:
    """add_samples as a renderer's: GPU ms a dispatch, counted; ctx.info names the device."""
    def __init__(self, device: str, ms: float):
        from types import SimpleNamespace
        self.ctx = SimpleNamespace(info={"GL_RENDERER": device})
        self.ms, self.calls = ms, 0

    def add_samples(self, n):
        self.calls += 1
        return self.ms


def test_the_warm_up_waits_for_a_gpus_clock_not_for_llvmpipes():
    """records.warm_up: on a GPU at least WARM_UP_WALL_S of wall time (its clock needs it to come
    back up after an idle second), however little GPU time each dispatch takes; on llvmpipe
    WARM_UP_MS of GPU work or WARM_UP_DISPATCHES, as before."""
    import time

    from radiance_probes.bench import records
    gpu = _WarmUpRenderer("NVIDIA H100 80GB HBM3/PCIe/SSE2", ms=0.5)
    start = time.perf_counter()
    warm = records.warm_up(gpu, 16)
    assert time.perf_counter() - start >= records.WARM_UP_WALL_S
    assert warm >= records.WARM_UP_MS and gpu.calls > records.WARM_UP_DISPATCHES
    cpu = _WarmUpRenderer("llvmpipe (LLVM 15.0.6, 256 bits)", ms=0.5)
    assert records.warm_up(cpu, 16) == 0.5 * records.WARM_UP_DISPATCHES
    assert cpu.calls == records.WARM_UP_DISPATCHES
    slow = _WarmUpRenderer("llvmpipe (LLVM 15.0.6, 256 bits)", ms=30.0)
    assert records.warm_up(slow, 16) == 60.0 and slow.calls == 2


def test_the_replay_moves_an_area_light_only_where_one_is_on():
    """interact.py's light_move: the first area light turned 30 degrees about the vertical axis
    (its height and distance kept); a scene without one is not given the edit."""
    import math
    from radiance_probes.bench.interact import EDITS, edit, edits_for
    from radiance_probes.io.scene_file import parse_scene
    lit = parse_scene({"area_lights": [{"shape": "sphere", "position": [1.5, 1.0, 0.0], "size": 0.2}]})
    assert edits_for(lit) == (*EDITS, "light_move")
    assert edits_for(parse_scene({})) == EDITS
    moved = edit(lit, "light_move").area_lights[0].position
    assert moved[1] == 1.0 and math.isclose(math.hypot(moved[0], moved[2]), 1.5)
    assert math.isclose(math.degrees(math.atan2(-moved[2], moved[0])), 30.0)


def test_the_replay_raises_a_gpus_clock_before_each_event_not_llvmpipes(ctx, monkeypatch):
    """interact.warm_clock: nothing on a CPU rasteriser; on a GPU, GPU work for CLOCK_WARM_S of
    wall time (the frames of an event then start at the working clock)."""
    from radiance_probes.bench import interact
    from radiance_probes.gl import context
    from radiance_probes.io.scene_file import parse_scene
    from radiance_probes.rendering.renderer import Renderer
    r = Renderer(ctx, parse_scene({"volume": {"builtin": "cloud", "size": [8, 8, 8]}}))
    try:
        assert interact.warm_clock(r, 256) == 0.0
        monkeypatch.setattr(context, "is_software", lambda ctx: False)
        monkeypatch.setattr(interact, "CLOCK_WARM_S", 0.05)
        assert interact.warm_clock(r, 256) >= 50.0
    finally:
        r.release()


def test_a_denoised_replay_refuses_to_run_without_the_denoiser(monkeypatch):
    """interact.require_denoiser: with the Denoise switch on and a denoiser that cannot run, the
    replay stops with the denoiser's own reason, not records of raw images taken as denoised;
    with it off (or left as the viewer's) nothing is asked."""
    from types import SimpleNamespace

    from radiance_probes.bench import interact
    from radiance_probes.viewer.frame import denoise_view

    class Missing:
        available = False
        failure = "the denoiser is not available (ImportError: no pyoidn)"
    monkeypatch.setattr(denoise_view, "shared_denoiser", lambda: Missing())
    with pytest.raises(RuntimeError, match="Denoise switch on.*no pyoidn"):
        interact.require_denoiser(SimpleNamespace(interact_denoise=True))
    interact.require_denoiser(SimpleNamespace(interact_denoise=False))
    interact.require_denoiser(SimpleNamespace(interact_denoise=None))
