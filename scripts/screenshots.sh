#!/usr/bin/env bash
# Regenerates screenshots/ with the CLI. Datasets come from ../shared/datasets (skipped if absent).
set -euo pipefail
cd "$(dirname "$0")/.."
rp=.venv/bin/radiance-probes
mkdir -p screenshots
$rp render --spp 256 --out screenshots/default_pt.png
if [ -f ../shared/datasets/bonsai_256x256x256_uint8.raw ]; then
  $rp render assets/scenes/bonsai.json --spp 128 --out screenshots/bonsai_pt.png
fi
