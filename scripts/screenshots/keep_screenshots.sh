#!/usr/bin/env bash
# Screenshots of issue 32's features (llvmpipe: a few minutes): the viewer with a crop box, a clip
# plane and their handles (screenshots/viewer_crop.png); the transfer-function editor with colour
# points and a point's colour picker open (screenshots/viewer_colour_points.png); a frame of a
# turntable movie with its colour bar (screenshots/movie_frame_colorbar.png, from
# `radiance-probes animate`). Uses bonsai from ../shared/datasets when present, else the built-in
# default scene. Runs in a private Xvfb when there is no display. SPP=... (default 32).
set -euo pipefail
cd "$(dirname "$0")/../.."
rp=.venv/bin/radiance-probes
spp=${SPP:-32}
scene=
crop="--crop-voxels 0 0 0 64 64 40"
plane="--clip-plane -1 0 0.25 0.15"
if [ -f ../shared/datasets/bonsai_256x256x256_uint8.raw ]; then
  scene=assets/scenes/bonsai.json
  crop="--crop-voxels 0 0 0 256 256 150"
fi
mkdir -p screenshots
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cat > "$tmp/crop.json" <<JSON
[
  {"click": "Crop and clip"}, {"until": "done"},
  {"screenshot": "$PWD/screenshots/viewer_crop.png"}, {"close": true}
]
JSON
$rp view $scene $crop $plane --script "$tmp/crop.json" --spp "$spp" --window 1280x800
cat > "$tmp/points.json" <<JSON
[
  {"click": "Edit colours as points"}, {"drag": "colour point 2", "by": [-40, 0]},
  {"until": "done"}, {"click": "colour point 3"}, {"frames": 2},
  {"screenshot": "$PWD/screenshots/viewer_colour_points.png"}, {"close": true}
]
JSON
$rp view $scene --script "$tmp/points.json" --spp "$spp" --window 1280x800
# A 12-frame turntable to numbered PNGs with the colour bar; its fourth frame is the picture.
$rp animate $scene $crop --frames 12 --spp 8 --width 640 --height 480 --colorbar \
  --out "$tmp/frames"
cp "$tmp/frames/frame_0003.png" screenshots/movie_frame_colorbar.png
echo "wrote screenshots/viewer_crop.png, viewer_colour_points.png, movie_frame_colorbar.png"
