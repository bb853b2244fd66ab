"""Does the raymarcher's per-sample drift follow the 64^3 x 256 setting, or the first session of a
run (the one that renders the references)? Two interact runs on bonsai at 1920x1080 (raymarch only):
A) 128^3x64 first, then 64^3x256, rendering references; B) 64^3x256 first, then 128^3x64, with
A's references (--ref-dir: nothing rendered during the sessions). Run on the GPU:
    python lab/experiments/experiment_interact_order.py OUT.json
(committed: bench/h100-interact-order: the summary per event, min / median / max GPU ms per
sample and the frame p99, and both runs' results.json)."""
import json
import statistics
import sys
sys.path.insert(0, ".")
from radiance_probes.bench.config import PRESETS  # noqa: E402
from radiance_probes.bench.runner import run_bench  # noqa: E402
out = sys.argv[1]
base = PRESETS["interact"].scaled(scenes=("bonsai",), interact_sizes=((1920, 1080),),
                                  interact_methods=("raymarch",))
a = base.scaled(interact_probes=((128, 64), (64, 256)))
run_bench(a, "/tmp/ordA", command="A")
b = base.scaled(interact_probes=((64, 256), (128, 64)), reference_dir="/tmp/ordA")
run_bench(b, "/tmp/ordB", command="B")
summary = {}
for tag in ("A", "B"):
    d = json.load(open(f"/tmp/ord{tag}/results.json"))
    for rec in d["records"]:
        if rec.get("mode") != "interact" or "frame_trace" not in rec or rec["method"] != "raymarch":
            continue
        per = [f[1] / f[2] for f in rec["frame_trace"] if f[2] > 0]
        key = f"{tag} {rec['probe_grid']}x{rec['probe_samples']} {rec['event']} {rec['variant']}"
        summary[key] = [round(min(per), 2), round(statistics.median(per), 2), round(max(per), 2),
                        round(rec["frame_ms_p99"], 1)]
        print(key, summary[key], flush=True)
    for rec in d["records"]:
        if rec.get("event") == "dispatch_tail":
            print(tag, rec["probe_grid"], rec["method"], rec["ms_per_sample_1"], flush=True)
json.dump(summary, open(out, "w"), indent=1)
