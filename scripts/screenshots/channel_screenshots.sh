#!/usr/bin/env bash
# Screenshots of issue 33's features (llvmpipe: a few minutes): the viewer showing a synthetic
# three-channel "cell" volume (nuclei, membranes, fibres: one panel a channel, each in its own
# colour, mixed by extinction where they meet; screenshots/viewer_channels.png), and a time series
# paused at one step with its Time panel (screenshots/viewer_time_series.png). The volumes are
# made by the script (NumPy), so it needs no dataset. Runs in a private Xvfb when there is no
# display. SPP=... (default 32).
set -euo pipefail
cd "$(dirname "$0")/../.."
rp=.venv/bin/radiance-probes
spp=${SPP:-32}
mkdir -p screenshots
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
.venv/bin/python - "$tmp" <<'PY'
import json, sys
import numpy as np
tmp = sys.argv[1]
n = 64
z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for _ in range(3)), indexing="ij")
rng = np.random.default_rng(3)
nuclei, membranes = np.zeros((n,) * 3), np.zeros((n,) * 3)
for _ in range(7):
    c = rng.uniform(-0.55, 0.55, 3)
    r = np.sqrt((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2)
    nuclei = np.maximum(nuclei, np.clip(1 - r / 0.16, 0, 1))
    membranes = np.maximum(membranes, np.exp(-((r - 0.3) / 0.025) ** 2))
fibres = np.zeros((n,) * 3)
for _ in range(5):
    a, d = rng.uniform(-0.7, 0.7, 3), rng.normal(size=3)
    d /= np.linalg.norm(d)
    p = np.stack([x, y, z], -1) - a
    dist = np.linalg.norm(p - (p @ d)[..., None] * d, axis=-1)
    fibres = np.maximum(fibres, np.exp(-(dist / 0.03) ** 2))
cells = (4000 * np.stack([nuclei, membranes, fibres])).astype(np.uint16)
np.save(f"{tmp}/cells.npy", cells)
tf = lambda rgb, a=1.0: {"colors": [[0, *rgb]], "opacity": [[0, 0], [0.25, 0], [1, a]]}
json.dump({"volume": {"path": "cells.npy", "axes": "czyx"}, "density_scale": 60,
           "albedo": 0.95,
           "channels": [{"name": "nuclei", "transfer_function": tf([0.3, 0.55, 1.0])},
                        {"name": "membranes", "transfer_function": tf([1.0, 0.35, 0.75], 0.08)},
                        {"name": "fibres", "transfer_function": tf([0.4, 1.0, 0.45])}],
           "camera": {"eye": [0.4, 0.5, 2.0]}}, open(f"{tmp}/cells.json", "w"))
steps = [np.roll(np.roll(cells[0], 3 * t, axis=2), t, axis=1) for t in range(8)]
np.save(f"{tmp}/series.npy", np.stack(steps))
json.dump({"volume": {"path": "series.npy", "axes": "tzyx"}, "density_scale": 60,
           "time": 5, "transfer_function": {"colormap": "viridis",
                                            "opacity": [[0, 0], [0.25, 0], [1, 1]]},
           "camera": {"eye": [0.4, 0.5, 2.0]}}, open(f"{tmp}/series.json", "w"))
PY
cat > "$tmp/channels.json" <<JSON
[
  {"until": "done"}, {"screenshot": "$PWD/screenshots/viewer_channels.png"}, {"close": true}
]
JSON
(cd "$tmp" && "$OLDPWD/$rp" view cells.json --script channels.json --spp "$spp" --method raymarch \
  --window 1280x800)
cat > "$tmp/time.json" <<JSON
[
  {"until": "done"},
  {"screenshot": "$PWD/screenshots/viewer_time_series.png"}, {"close": true}
]
JSON
(cd "$tmp" && "$OLDPWD/$rp" view series.json --script time.json --spp "$spp" --method raymarch \
  --window 1280x800)
echo "wrote screenshots/viewer_channels.png, viewer_time_series.png"
