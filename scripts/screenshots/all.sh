#!/usr/bin/env bash
# Regenerates every picture in screenshots/ (the README's and docs' images), one maker after another.
#   bash scripts/screenshots/all.sh [--cpu] [--bench-images DIR] [--denoise-images DIR]
# The first five makers run anywhere (llvmpipe: about 15 minutes together). The rest are the
# reference-quality comparisons, thousands of path-traced samples each: on llvmpipe they take
# hours, so `--cpu` skips them (and says so). methods_*.png and denoise_*.png are montages of a
# benchmark run's images: give the runs' images/ folders, or the script runs the two presets
# (`bench --preset gpu` and `bench --preset denoise`, on a GPU) into /tmp first.
# Datasets come from ../shared/datasets; a maker whose dataset is absent skips it and says so.
set -euo pipefail
cd "$(dirname "$0")/../.."
here=scripts/screenshots
py=.venv/bin/python
rp=.venv/bin/radiance-probes
cpu=0; bench_images=""; denoise_images=""
while [ $# -gt 0 ]; do
  case "$1" in
    --cpu) cpu=1 ;;
    --bench-images) bench_images="$2"; shift ;;
    --denoise-images) denoise_images="$2"; shift ;;
    *) echo "all.sh: unknown argument $1 (see the header)" >&2; exit 2 ;;
  esac
  shift
done
bash $here/screenshots.sh           # default_*, sky_envmap, visibility_leak, bonsai_pt
bash $here/viewer_screenshots.sh    # viewer_pt, viewer_split, viewer_error, viewer_probe_grid
bash $here/keep_screenshots.sh      # viewer_crop, viewer_colour_points, movie_frame_colorbar
bash $here/channel_screenshots.sh   # viewer_channels, viewer_time_series
$py $here/format_screenshots.py     # viewer_dicom_*, viewer_nifti_mri, viewer_slices
if [ "$cpu" = 1 ]; then
  echo "all.sh: --cpu: skipped the GPU makers (accuracy_*, sh_orders_*, final_gather, equal_time_*," \
       "surfaces_*, methods_*, denoise_*)" >&2
  exit 0
fi
$py $here/accuracy_screenshots.py screenshots
$py $here/sh_order_screenshots.py screenshots
$py $here/gather_screenshots.py screenshots
$py $here/equal_time_screenshots.py screenshots
$py $here/surface_screenshots.py screenshots
if [ -z "$bench_images" ]; then
  $rp bench --preset gpu --out /tmp/rp-bench-gpu && bench_images=/tmp/rp-bench-gpu/images
fi
$py $here/bench_montage.py "$bench_images" screenshots
if [ -z "$denoise_images" ]; then
  $rp bench --preset denoise --scenes bonsai,anisotropic --out /tmp/rp-bench-denoise \
    && denoise_images=/tmp/rp-bench-denoise/images
fi
$py $here/denoise_screenshots.py "$denoise_images" screenshots
echo "all.sh: screenshots/ regenerated"
