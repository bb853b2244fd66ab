"""How much of `guided`'s level 0 (frames of an unbiased estimate of what the probes predict
along camera rays, lib/guided_level0.glsl) is due when level 1 has a given number of samples.

Level 0 gets `ratio` frames per sample of level 1 (RenderSettings.guided_level0_ratio), counted
in work groups (tiles of 8 x 8 pixels, sample_bands.tile_grid), so that a frame may be marched
in bands (Raymarcher.run_groups: each pixel its own running mean):

- whole frames (a still image, `bands` False): ceil(samples x ratio) frames, each dispatched whole
  when it falls due;
- in bands (the viewer, `bands` True): at least those frames, and the next frame's groups spread
  over the samples before it falls due, so that each sample pays `ratio` of a frame. On the
  H200 at 1920x1080 a whole level-0 frame took 20-23 ms against a level-1 sample's 6 ms, every
  fourth guided frame of the viewer's refine (bench/h200-interact-refine-56: the p99 frames).

The first frame is whole either way: guided's image (level 0 plus level 1) is read only once
every pixel has a level-0 frame."""
from __future__ import annotations

import math


def level0_groups_due(samples: int, ratio: float, groups_per_frame: int,
                      bands: bool) -> int:
    """Work groups of level 0 in all (whole frames x groups_per_frame plus those of the frame in
    progress) due when level 1 holds `samples` samples."""
    if samples <= 0:
        return 0
    frames = math.ceil(samples * ratio)
    whole = max(1, frames) * groups_per_frame
    if not bands:
        return whole
    # the frame due after `samples / ratio` samples, begun a sample of level 1 after the last one
    # fell due: (samples x ratio + 1 - ratio) frames, rounded up to whole groups
    spread = math.ceil((samples * ratio + 1.0 - min(ratio, 1.0)) * groups_per_frame - 1e-6)
    return max(whole, spread)
