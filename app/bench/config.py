"""What a benchmark run measures: the paper's Table 1 axes (probe grid x samples per probe), the path
tracer's samples per pixel, the raymarcher's step and stage. Two presets: `gpu` for the lent GPU and
`quick` for llvmpipe (small images and grids, the same code)."""
from __future__ import annotations

from dataclasses import dataclass, replace

from radiance_probes.bench.scenes import ALL_SCENES, BATTERY_SCENES
from radiance_probes.rendering.budgets.frame_budget import BAKE_BUDGET_MS, FRAME_BUDGET_MS

# The sweep's probe layouts (`--probe-layouts`): "uniform", or an adaptive layout driven by that
# indicator (app/rendering/probes/planes.py), each at the same probe counts.
BENCH_PROBE_LAYOUTS = ("uniform", "extinction", "sun")


@dataclass(frozen=True)
class BenchConfig:
    scenes: tuple[str, ...] = ALL_SCENES
    width: int = 512
    height: int = 512
    ref_spp: int = 32768                 # path-traced reference, split into two independent halves
    ref_samples_per_pass: int = 128      # samples per pixel in one dispatch for the reference
    pt_spp: tuple[int, ...] = (1, 4, 16, 64, 256, 1024, 4096)   # 4096: where 2% and 1% lie
    samples_per_dispatch: int = 16          # every progressive method, PT included
    probe_grids: tuple[int, ...] = (8, 16, 32, 64)
    probe_samples: tuple[int, ...] = (16, 64, 128, 256, 512)
    # (grid, samples) extras; the finest probe spacings fine structure asks for
    large_grids: tuple[tuple[int, int], ...] = ((128, 64), (128, 256), (192, 64), (256, 16))
    probe_frames: tuple[int, ...] = (1, 4, 16, 64, 256)  # probes / probes-only snapshots
    # `probes` with a final gather (Renderer.probe_gather_event, lib/integrator.glsl): at these
    # probe settings, each gather event also runs, to these frames (its error keeps falling long
    # after the first event's levels off: bench/h100-final-gather)
    gather_events: tuple[int, ...] = (2, 3)
    gather_settings: tuple[tuple[int, int], ...] = ((32, 256), (64, 128), (128, 64), (128, 256))
    gather_frames: tuple[int, ...] = (16, 64, 256, 1024, 4096)
    # `guided` (unbiased: level 0 from the probes plus a path-traced correction) at these probe
    # settings, to these samples per pixel
    guided_settings: tuple[tuple[int, int], ...] = ((32, 256), (64, 128))
    guided_frames: tuple[int, ...] = (4, 16, 64, 256, 1024, 4096)
    raymarch_frames: tuple[int, ...] = (1, 2, 4, 8, 16)
    showcase: tuple[int, int] = (32, 256)   # grid, samples: images, step/stage/precision sweeps
    probe_layouts: tuple[str, ...] = ("uniform",)   # of BENCH_PROBE_LAYOUTS, per probe setting
    adaptive_strength: float | None = None  # the adaptive layouts' strength (None: the scene's)
    sh_orders: tuple[int, ...] = ()         # SH orders each probe setting also runs with (--sh-orders)
    probe_precision: str | None = None   # the sweep's probe textures (None: the scene's, rgba32f)
    raymarch_steps: tuple[float, ...] = (0.25, 0.5, 1.0, 2.0)   # the showcase setting's
    # The raymarcher's steps (voxels) at every probe setting: the step is a setting like the grid
    # and the walks (a coarser one is a cheaper frame for more error), so the time to reach an
    # error takes the best of them. 0.5, the default, first.
    sweep_raymarch_steps: tuple[float, ...] = (0.5, 1.0, 2.0)
    flip_frames: tuple[int, ...] = (16, 256)   # FLIP only at these snapshots (it costs CPU time)
    image_frames: int = 64                  # snapshot saved as PNG for the showcase images
    mode: str = "sweep"                     # "sweep": every method and setting; "cost": cost.py;
                                            # "bake": the bake's profile (bake.py)
    reference_dir: str | None = None        # reuse an earlier run's refs/ and measured noise
    cost_settings: tuple[tuple[int, int], ...] = ((32, 256), (64, 256))  # grid, samples
    cost_probe_frames: int = 64
    cost_raymarch_frames: int = 16
    cost_pt_spp: int = 256
    cost_auto_targets: tuple[float, ...] = (0.05, 0.10)   # `auto` checked at full resolution
    # ... after these many raymarched frames: the pilot's trials take 256 (auto_probes.py
    # PILOT_FRAMES), so the last count judges the probes rather than the frames' own sampling
    auto_check_frames: tuple[int, ...] = (16, 64)
    # `--auto-probes`' pilot in cost mode: its side in pixels and each trial's frames there
    # (auto_probes.py PILOT_SIDE, PILOT_FRAMES, the defaults; the tests' tiny runs use fewer)
    auto_pilot_side: int = 96
    auto_pilot_frames: int = 256
    bake_settings: tuple[tuple[int, int], ...] = ((32, 256), (64, 512), (128, 256))  # grid, walks
    # (sun at walk events, light grid texels per axis at most, adaptive walks factor) per bake
    # setting; see bake.py
    bake_variants: tuple[tuple[str, int, float], ...] = (
        ("ray", 128, 0.0), ("ray", 512, 0.0), ("grid", 512, 0.0), ("grid", 512, 1.0))
    bake_repeats: int = 3                   # bakes timed per setting (the median is reported)
    ceiling_rays: int = 1 << 21             # rays of the ceiling's trilinear march (256 steps each)
    # rays of the speed check before each setting (ceiling.py speed_check_ms; 64 steps each)
    speed_check_rays: int = 1 << 18         # ceiling.SPEED_CHECK_RAYS, the default
    code_label: str = "current"             # names the code a bake run measured (before/after)
    # --preset interact (interact.py): the replayed viewer session
    interact_sizes: tuple[tuple[int, int], ...] = ((1920, 1080), (1280, 720))
    # probe settings replayed, each (grid, walks per probe)
    interact_probes: tuple[tuple[int, int], ...] = ((64, 256), (128, 64))
    interact_bake_budget_ms: float = BAKE_BUDGET_MS["gpu"]     # GPU time a frame gives the bake
    interact_frame_budget_ms: float = FRAME_BUDGET_MS["gpu"]   # ... and a frame in all (session.py)
    # refine: guided's samples once it has replaced the raymarcher
    interact_target_spp: tuple = (("probes", 64), ("raymarch", 16), ("pt", 256), ("refine", 256))
    # the methods the session is replayed with (load, orbit, edits), each against the same
    # references: the viewer's (app/methods.py VIEWER_METHODS), `refine` included
    # (`bench --methods`)
    interact_methods: tuple[str, ...] = ("probes", "raymarch")
    interact_max_frames: int = 300                   # frames an event may take to converge
    interact_orbit_frames: int = 60
    interact_ref_spp: int = 1024                     # reference per event state (two halves)
    interact_tail_k: int = 8                         # samples per dispatch against 1
    interact_flicker_frames: int = 24                # refine's still-camera flicker window (0: none)
    # the replay's parts to run (None: all): "load" (with orbit and the edits), "flicker",
    # "raymarch_switch" (with the dispatch tail)
    interact_events: tuple | None = None
    # reference samples per event state by scene, beside interact_ref_spp (a noisy scene's own)
    interact_ref_spp_by_scene: tuple = ()
    # the viewer's Denoise switch in the replay (None: its default, on on a GPU); the errors are
    # then the shown (filtered) image's, and a frame's time adds the filtering's wall ms
    interact_denoise: bool | None = None
    # the bake's slice takes the frame but one preview sample while every view restarts after
    # it (RenderSession.bake_fills_frame, the viewer's); False: bake_budget_ms as before issue 56
    interact_bake_fills_frame: bool = True
    # --preset movie (movie.py): a turntable raymarched over probes baked once, timed whole,
    # its error at a few frames against path-traced references, the path tracer's time beside
    movie_frames: int = 120
    movie_degrees: float = 360.0
    movie_spp: int = 16                              # raymarched frames accumulated per frame
    movie_probes: tuple[int, int] = (128, 64)        # the viewer's GPU default (device_defaults)
    movie_check_frames: tuple[int, ...] = (0, 40, 80)
    movie_ref_spp: int = 8192                        # per check frame, in two halves
    movie_pt_max_spp: int = 8192                     # the path tracer's progressive run at most
    movie_fps: float = 30.0
    movie_target: float = 0.05                       # per-frame relative RMSE asked for
    # --preset bias (bias.py): each default shortcut against its exact variant on the battery
    bias_settings: tuple[tuple[int, int], ...] = ((32, 256),)   # grid, walks (the held-out check)
    bias_seeds: int = 4                              # independent bakes per variant (paired)
    bias_frames: int = 16                            # raymarched frames per image
    bias_probe_spp: int = 64                         # `probes` samples per image
    # --preset denoise (denoise.py): each noisy method raw and denoised with each guide set
    denoise_guides: tuple[str, ...] = ("none", "albedo", "albedo-normal", "probes")
    denoise_quality: str = "high"
    # the "probes" guide's (grid, walks) settings, each a guide of its own
    denoise_guide_probes: tuple[tuple[int, int], ...] = ((64, 128), (32, 64))
    denoise_probe_setting: tuple[int, int] = (64, 128)    # `probes` at its first event
    denoise_gather_setting: tuple[int, int] = (128, 64)   # `probes` with a gather (gather_events)
    denoise_guided_setting: tuple[int, int] = (64, 128)
    denoise_cost: bool = True                             # the cost table at 512^2, 1080p, 4K
    denoise_flicker_spp: tuple[int, ...] = (4, 16)        # flicker: the path tracer at these spp
    denoise_flicker_frames: int = 8                       # ... this many independent images each

    def scaled(self, **changes) -> "BenchConfig":
        return replace(self, **changes)


PRESETS = {
    "gpu": BenchConfig(),
    "cost": BenchConfig(mode="cost"),
    # empty-space skipping on and off, one probe setting, no auto: a short run
    "skipping": BenchConfig(mode="cost", cost_settings=((32, 256),), cost_auto_targets=()),
    # `auto` alone, checked at full resolution
    "auto": BenchConfig(mode="cost", cost_settings=(), cost_auto_targets=(0.05, 0.10)),
    # the bake's profile against the GPU's ceiling, with the raymarcher's error (bake.py)
    "bake": BenchConfig(mode="bake", scenes=("bonsai", "fuel", "hydrogen", "foot"), ref_spp=16384,
                        raymarch_frames=(16,)),
    # issue 29's "no floor": the path tracer and `guided` run on to 32768 samples per pixel, `probes`
    # with a final gather to 16384, beside a short sweep of the raymarcher's and the probes'
    # settings, so that the report's convergence table shows which errors keep falling (1 to 2.5
    # minutes a scene on an H100, most of it the reference and the long runs)
    "convergence": BenchConfig(pt_spp=(1, 4, 16, 64, 256, 1024, 4096, 16384, 32768),
                               probe_grids=(32,), probe_samples=(64, 256),
                               large_grids=((128, 64),), gather_settings=((128, 64),),
                               gather_frames=(16, 64, 256, 1024, 4096, 16384),
                               guided_settings=((32, 256),),
                               guided_frames=(4, 16, 64, 256, 1024, 4096, 16384, 32768),
                               showcase=(0, 0), sweep_raymarch_steps=(0.5,), flip_frames=()),
    # the replayed viewer session (interact.py), two probe settings: about 4 minutes a scene on
    # an H100, a third of it the 12 references per scene (--ref-dir reuses them)
    "interact": BenchConfig(mode="interact", scenes=("bonsai", "foot"), ref_samples_per_pass=64),
    # the same session on llvmpipe: small images and probes (warm against cold at small size)
    "interact-quick": BenchConfig(mode="interact", scenes=("anisotropic", "thick"),
                                  interact_sizes=((64, 48),), interact_probes=((8, 128),),
                                  interact_bake_budget_ms=40.0, interact_frame_budget_ms=45.0,
                                  interact_target_spp=(("probes", 16), ("raymarch", 4),
                                                       ("refine", 64)),
                                  interact_methods=("probes", "raymarch", "refine"),
                                  interact_max_frames=60, interact_orbit_frames=12,
                                  interact_ref_spp=512, ref_samples_per_pass=16, interact_tail_k=4,
                                  interact_flicker_frames=4, speed_check_rays=1 << 12),
    # the viewer's refine on the GPU at 1080p, the viewer's GPU probe default (128^3 x 64): is it
    # within 2% of the reference within 1 s of every edit? (about 2 minutes a scene on an H100; the
    # chest CT under a sphere light adds an edit that moves the light). References: bonsai's and
    # the chest's at 1024 spp had 1.2% and 1.3-1.9% noise of their own (against a 2% target), so
    # theirs take 2048 and 4096 (about 0.85% and 0.7-0.95%).
    "interact-refine": BenchConfig(mode="interact", scenes=("bonsai", "foot", "chest"),
                                   ref_samples_per_pass=64, interact_sizes=((1920, 1080),),
                                   interact_probes=((128, 64),), interact_methods=("refine",),
                                   interact_ref_spp_by_scene=(("bonsai", 2048), ("chest", 4096))),
    # its flicker measurement alone, on the loaded scene (interact.still_flicker)
    "interact-refine-flicker": BenchConfig(mode="interact", scenes=("bonsai", "foot", "chest"),
                                           ref_samples_per_pass=64, interact_sizes=((1920, 1080),),
                                           interact_probes=((128, 64),), interact_methods=("refine",),
                                           interact_ref_spp_by_scene=(("bonsai", 2048),
                                                                      ("chest", 4096)),
                                           interact_events=("flicker",)),
    # the raymarcher, the image shown while anything moves, at 3840x2160: its frames' p99 in every
    # event (the goal: at most 16 ms)
    "interact-raymarch-4k": BenchConfig(mode="interact", scenes=("bonsai", "foot", "chest"),
                                        ref_samples_per_pass=64, interact_sizes=((3840, 2160),),
                                        interact_probes=((128, 64),), interact_methods=("raymarch",),
                                        interact_ref_spp=256),
    # the same with the Denoise switch off (what the viewer showed before it had one)
    "interact-refine-raw": BenchConfig(mode="interact", scenes=("bonsai", "foot"),
                                       ref_samples_per_pass=64, interact_sizes=((1920, 1080),),
                                       interact_probes=((128, 64),), interact_methods=("refine",),
                                       interact_denoise=False),
    # the movie of the issue: 120 frames of bonsai at 1080p on the lent GPU (about 4 minutes,
    # most of it the three references and the path tracer's runs)
    "movie": BenchConfig(mode="movie", scenes=("bonsai",), width=1920, height=1080,
                         ref_samples_per_pass=64),
    # the same at tiny size for llvmpipe (a test runs it)
    "movie-quick": BenchConfig(mode="movie", scenes=("tiny",), width=48, height=32,
                               movie_frames=12, movie_spp=4, movie_probes=(8, 32),
                               movie_check_frames=(0, 6), movie_ref_spp=256,
                               movie_pt_max_spp=256, ref_samples_per_pass=16,
                               samples_per_dispatch=8),
    # the bias table over the stress battery (bias.py): 256^2, references of 16384 spp
    "bias": BenchConfig(mode="bias", scenes=BATTERY_SCENES, width=256, height=256, ref_spp=16384,
                        ref_samples_per_pass=256),
    "bias-quick": BenchConfig(mode="bias", scenes=BATTERY_SCENES, width=32, height=32,
                              ref_spp=256, ref_samples_per_pass=64, bias_settings=((4, 64),),
                              bias_seeds=2, bias_frames=2, bias_probe_spp=2),
    # the denoiser over every noisy method on the seven bench scenes (denoise.py); the gather at
    # event 3 too, to 2048 frames: its bias floor is below 1% where event 2's is not
    # (bench/h100-final-gather: bonsai 0.71% against 0.93% at 4096 frames)
    "denoise": BenchConfig(mode="denoise", ref_spp=16384, ref_samples_per_pass=256,
                           pt_spp=(1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096),
                           probe_frames=(4, 16, 64, 256),
                           gather_events=(2, 3), gather_frames=(4, 16, 64, 256, 1024, 2048),
                           guided_frames=(4, 16, 64, 128, 256, 1024), raymarch_frames=(4, 16),
                           flip_frames=(16, 256), image_frames=64),
    # the denoiser's bias on the stress battery (a denoised image's mean against the raw one's)
    "denoise-battery": BenchConfig(mode="denoise", scenes=BATTERY_SCENES, width=256, height=256,
                                   ref_spp=8192, ref_samples_per_pass=256,
                                   pt_spp=(4, 16, 64, 256, 1024), probe_frames=(4, 64),
                                   gather_events=(2, 3), gather_frames=(16, 256),
                                   guided_frames=(16, 256), raymarch_frames=(16,),
                                   denoise_guide_probes=((32, 64),), denoise_probe_setting=(32, 64),
                                   denoise_gather_setting=(32, 64),
                                   denoise_guided_setting=(32, 64), denoise_cost=False,
                                   flip_frames=(), image_frames=64, denoise_flicker_spp=()),
    "denoise-quick": BenchConfig(mode="denoise", scenes=("tiny",), width=32, height=32,
                                 ref_spp=256, ref_samples_per_pass=32, pt_spp=(4, 16),
                                 probe_frames=(4,), gather_events=(2,), gather_frames=(4,),
                                 guided_frames=(4,), raymarch_frames=(2,), flip_frames=(16,),
                                 image_frames=16, samples_per_dispatch=4,
                                 denoise_guide_probes=((4, 32),), denoise_probe_setting=(4, 32),
                                 denoise_gather_setting=(4, 16), denoise_guided_setting=(4, 32),
                                 denoise_cost=False, speed_check_rays=1 << 12,
                                 denoise_flicker_spp=(4,), denoise_flicker_frames=3),
    "quick": BenchConfig(width=96, height=96, ref_spp=2048, ref_samples_per_pass=16,
                         speed_check_rays=1 << 12,
                         pt_spp=(1, 4, 16), samples_per_dispatch=4, probe_grids=(4, 8), probe_samples=(16, 64),
                         large_grids=(), probe_frames=(1, 4, 16), raymarch_frames=(1, 4),
                         gather_events=(2,), gather_settings=((8, 64),), gather_frames=(4, 16),
                         guided_settings=((8, 64),), guided_frames=(4, 16),
                         showcase=(8, 64), raymarch_steps=(0.5, 1.0),
                         sweep_raymarch_steps=(0.5, 1.0), flip_frames=(16,),
                         image_frames=16),
}
