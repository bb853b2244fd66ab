"""`auto`: the cheapest probe setting that meets a target error, chosen from measurements the
renderer makes itself, with the reasons written down.

1. Representation, from the scene alone: SH order 0 when g = 0 (exact, probe_layout.py), else 2,
   or 3 for strongly anisotropic scenes and probes of 128 walks or more (resolve_sh_order);
   RGBA16F (the benchmark measured the same error as 32F at half the memory); the grid fitted to
   the visible region.
2. A pilot: the scene's own view at low resolution, path traced until the reference's measured
   noise (two independent halves) is at most a fifth of the target.
3. Candidates in order of bake cost (probes x walks): for each grid (8^3 to 256^3, at most two
   probes a voxel along the volume's longest axis), the fewest walks whose image comes within
   PILOT_MARGIN x the target against the pilot. The first grid that meets it wins; if none does, the most
   accurate candidate is taken and the report says the target was not met.

The pilot's lower resolution averages away detail finer than its pixels, so the error it measures
can be lower than at full resolution: the benchmark checks the choice at full resolution.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from radiance_probes.rendering.metrics import reference_noise, rrmse
from radiance_probes.io.scene_file import Scene

# Up to 256 per axis (MAX_PROBE_AXIS): within 500 ms the benchmark's best bonsai and foot came from
# 192^3 and 256^3 grids. A grid with more than PROBES_PER_VOXEL_LIMIT probes per voxel along the
# volume's longest axis is not tried: the medium is trilinear between voxel centres, so light
# changes on the voxel scale, which probes at half a voxel's spacing already sample (fuel, 64^3
# voxels, reached 1% with 128^3 probes in the benchmark).
GRIDS = (8, 16, 32, 64, 128, 192, 256)
PROBES_PER_VOXEL_LIMIT = 2
WALKS = (16, 64, 256)
PILOT_SIDE = 96
PILOT_FRAMES = 256   # frames (samples per pixel) of each trial at the pilot's resolution
# The pilot must come within this fraction of the target: at 96 px it sees less fine detail than
# the full image, and on the benchmark its error was up to 3% below the full-resolution one.
PILOT_MARGIN = 0.9


@dataclass
class AutoChoice:
    scene: Scene                   # the input scene with the chosen probe settings
    target: float
    met: bool
    rrmse: float                   # the chosen setting's error against the pilot
    pilot_noise: float
    pilot_spp: int
    trials: list[dict] = field(default_factory=list)
    reasons: list[str] = field(default_factory=list)
    # GPU ms the choice cost: the pilot's path traces, every trial's bake (what its probes cost,
    # also when the renderer already held them) and every trial's pilot render.
    search_ms: float = 0.0

    def report(self, trials: bool = True) -> str:
        """The choice and why, then (trials=True) every setting tried; a caller that printed the
        trials as they came (progress) leaves them out."""
        from radiance_probes.rendering.probes.layout import resolve_sh_order
        p = self.scene.probes
        order = resolve_sh_order(p.sh_order, self.scene.anisotropy, p.samples)
        head = (f"auto: probes {p.grid[0]}^3 (fitted), {p.samples} walks, SH order {order}, "
                f"{p.precision}: rRMSE {self.rrmse:.4f} against a {self.pilot_spp}-spp pilot "
                f"(noise {self.pilot_noise:.4f}); target {self.target:.4f} "
                f"{'met' if self.met else 'NOT met'}")
        rows = [f"  tried {t['grid']}^3 x {t['walks']}: rRMSE {t['rrmse']:.4f}, bake "
                f"{t['bake_ms']:.1f} ms" for t in (self.trials if trials else ())]
        return "\n".join([head, *("  " + r for r in self.reasons), *rows])


def _pilot_scene(scene: Scene, side: int) -> Scene:
    cam = scene.camera
    scale = side / max(cam.width, cam.height)
    w, h = max(8, round(cam.width * scale)), max(8, round(cam.height * scale))
    return scene.replace(camera=replace(cam, width=w, height=h))


def choose_probes(renderer, target: float = 0.05, method: str = "raymarch",
                  grids=GRIDS, walks=WALKS, pilot_side: int = PILOT_SIDE,
                  max_pilot_spp: int = 1 << 16, frames: int | None = None,
                  progress=None) -> AutoChoice:
    """Measures and returns the cheapest probe setting for `method` that meets `target` (relative
    RMSE against a path-traced pilot). Leaves the renderer on the input scene."""
    if not 0 < target < 1:
        raise ValueError(f"auto target must be a relative RMSE in (0, 1), got {target}")
    original = renderer.scene
    order = "auto"
    reasons = [("SH order: 0, since g = 0 zeroes bands 1 and up" if original.anisotropy == 0 else
                "SH order: 2, or 3 where |g|^3 >= 0.2 and a candidate has 128 walks or more"),
               "precision: rgba16f (same error as 32F in the benchmark, half the memory)",
               "grid fitted to the visible region", "one channel when the scene is grey"]
    pilot = _pilot_scene(original, pilot_side)
    try:
        renderer.set_scene(pilot)
        # Pilot: double the samples until its own noise is at most target / 5.
        spp, halves, noise = 64, None, math.inf
        search_ms = 0.0
        while True:
            runs = [renderer.render("pt", spp=spp, seed=s, samples_per_pass=min(spp, 64))
                    for s in (901, 902)]
            search_ms += sum(r.render_ms for r in runs)
            halves = [r.image for r in runs]
            noise = reference_noise(*halves)
            if progress:
                progress(f"pilot {2 * spp} spp: noise {noise:.4f}")
            if noise <= target / 5 or 2 * spp >= max_pilot_spp:
                break
            spp *= 2
        reference = 0.5 * (halves[0] + halves[1])
        pilot_spp = 2 * spp
        # Enough frames that the trial's own sampling (the raymarcher's sub-pixel jitter, the
        # probe methods' paths) does not hide the probes' error: at the pilot's 96 px 16 frames
        # left bonsai at 2.7% where 256 give 1.1% (the full image, 16 frames: 1.15%).
        frames = frames or PILOT_FRAMES
        trials: list[dict] = []
        chosen = None
        voxels = max(renderer.resources.volume.dims)
        tried = [g for g in grids if g <= PROBES_PER_VOXEL_LIMIT * voxels] or [min(grids)]
        if len(tried) < len(grids):
            reasons.append(f"grids up to {max(tried)}^3: the volume has {voxels} voxels along its "
                           f"longest axis (at most {PROBES_PER_VOXEL_LIMIT} probes a voxel)")
        for grid in tried:
            best_here = None
            for n in walks:
                probes = replace(pilot.probes, grid=(grid, grid, grid), samples=n, sh_order=order,
                                 precision="rgba16f", fit="visible", channels="auto")
                renderer.set_scene(pilot.replace(probes=probes))
                renderer.bake(seed=7)
                # What these probes cost, also when the renderer held them already (an earlier
                # search baked the same setting): bake() then returns 0 and last_bake_ms keeps it.
                bake_ms = renderer.last_bake_ms
                run = renderer.render(method, spp=frames, seed=5, samples_per_pass=frames)
                search_ms += bake_ms + run.bake_ms + run.render_ms
                image = run.image
                err = rrmse(image, reference)
                trial = {"grid": grid, "walks": n, "rrmse": err, "bake_ms": bake_ms,
                         "probes": renderer.probe_grid.count}
                trials.append(trial)
                if progress:
                    progress(f"tried {grid}^3 x {n}: rRMSE {err:.4f}, bake {bake_ms:.1f} ms")
                if err <= PILOT_MARGIN * target:
                    best_here = trial
                    break          # fewer walks first: the first that meets it is the cheapest
            if best_here is not None:
                chosen = best_here
                break
        met = chosen is not None
        if not met:
            chosen = min(trials, key=lambda t: t["rrmse"])
            reasons.append("no candidate met the target; took the most accurate one")
        else:
            reasons.append(f"the coarsest grid, then the fewest walks, within {PILOT_MARGIN:g} x "
                           "the target on the pilot (a margin for detail the pilot cannot see)")
        if noise > target / 5:
            reasons.append(f"the pilot stopped at {pilot_spp} spp with noise {noise:.4f} "
                           f"(wanted {target / 5:.4f})")
        probes = replace(original.probes, grid=(chosen["grid"],) * 3, samples=chosen["walks"],
                         sh_order=order, precision="rgba16f", fit="visible", channels="auto")
        return AutoChoice(original.replace(probes=probes), target, met, chosen["rrmse"], noise,
                          pilot_spp, trials, reasons, search_ms)
    finally:
        renderer.set_scene(original)
