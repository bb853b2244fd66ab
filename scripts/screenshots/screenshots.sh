#!/usr/bin/env bash
# Regenerates screenshots/ with the CLI on whatever GL device is there (llvmpipe: several minutes).
# Datasets come from ../shared/datasets and are skipped when absent.
set -euo pipefail
cd "$(dirname "$0")/../.."
rp=.venv/bin/radiance-probes
py=.venv/bin/python
mkdir -p screenshots /tmp/rp-shots
$rp render --spp 256 --out screenshots/default_pt.png
# Path tracer against the three probe methods on the default scene (16^3 probes, 256 walks each).
for m in pt probes probes-only raymarch; do
  $rp render --method $m --spp 64 --width 256 --height 256 --probe-grid 16 --probe-samples 256 \
    --out /tmp/rp-shots/default_$m.png
done
$py scripts/screenshots/montage.py screenshots/default_methods.png /tmp/rp-shots/default_pt.png:"path tracer 64 spp" \
  /tmp/rp-shots/default_probes.png:"probes 64 spp" /tmp/rp-shots/default_probes-only.png:"probes-only 64 spp" \
  /tmp/rp-shots/default_raymarch.png:"raymarch 64 frames"
# The cloud under the procedural sky map (assets/scenes/sky.json): path tracer and raymarcher.
$rp render assets/scenes/sky.json --spp 256 --width 256 --height 256 --out /tmp/rp-shots/sky_pt.png
$rp render assets/scenes/sky.json --method raymarch --spp 16 --width 256 --height 256 \
  --out /tmp/rp-shots/sky_raymarch.png
$py scripts/screenshots/montage.py screenshots/sky_envmap.png /tmp/rp-shots/sky_pt.png:"path tracer 256 spp" \
  /tmp/rp-shots/sky_raymarch.png:"raymarch 16 frames"
# A wall in a thin medium: trilinear against visibility-weighted probe interpolation (~1 minute).
$py scripts/screenshots/visibility_screenshots.py screenshots
if [ -f ../shared/datasets/bonsai_256x256x256_uint8.raw ]; then
  $rp render assets/scenes/bonsai.json --spp 128 --out screenshots/bonsai_pt.png
fi
