#!/usr/bin/env bash
# Screenshots of the viewer (window with its panels, 1280x800) in each mode: path tracer, split
# view (pt | probes), error view (probes against pt) and the probe view (a 64^3 grid's slab).
# Uses bonsai from ../shared/datasets when present, else the built-in default scene. Runs in a
# private Xvfb when there is no display. On llvmpipe this takes a few minutes; SPP=... to change
# the samples per pixel (default 32).
set -euo pipefail
cd "$(dirname "$0")/../.."
spp=${SPP:-32}
scene=
if [ -f ../shared/datasets/bonsai_256x256x256_uint8.raw ]; then scene=assets/scenes/bonsai.json; fi
mkdir -p screenshots
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cat > "$tmp/script.json" <<JSON
[
  {"until": "done"}, {"screenshot": "$PWD/screenshots/viewer_pt.png"},
  {"key": "2"}, {"until": "done"}, {"key": "1"}, {"key": "s"}, {"until": "done"},
  {"screenshot": "$PWD/screenshots/viewer_split.png"},
  {"key": "2"}, {"key": "e"}, {"until": "done"}, {"screenshot": "$PWD/screenshots/viewer_error.png"},
  {"close": true}
]
JSON
.venv/bin/radiance-probes view $scene --script "$tmp/script.json" --spp "$spp" --window 1280x800
# The probe view at 64^3 (issue 43): one slab of probes (a plane across z) over the raymarched
# volume, the mouse on a probe so its tooltip shows what it holds. 8 walks a probe keep llvmpipe's
# bake to a couple of minutes; the view draws the probes, not their accuracy.
cat > "$tmp/probes.json" <<JSON
[
  {"key": "4"}, {"until": "baked"}, {"click": "probes over"}, {"click": "slab z"},
  {"until": "done"}, {"move": {"view": [0.49, 0.72]}}, {"frames": 2},
  {"screenshot": "$PWD/screenshots/viewer_probe_grid.png"},
  {"close": true}
]
JSON
.venv/bin/radiance-probes view $scene --script "$tmp/probes.json" --spp 4 --window 1280x800 \
  --probe-grid 64 --probe-samples 8
