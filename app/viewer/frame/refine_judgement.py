"""refine's checks and judgements over frames (app/viewer/frame/session.py): nothing in a frame waits
for the halves' sums, the filter or the judgement's sums (issue 56).

A check (RefineCheck) is begun on the frame whose combine reduced the halves' sums: their 16
bytes are copied into a buffer of the view's and fenced (app/gl/fence.py), and the session acts on
them (the estimate, the raw switch) on the first later frame that finds the fence signalled.
Where the check judges the blend (the Denoise switch on), the same frame's combine wrote half A
alone and half B is copied as it is (HalfBuffers.snapshot_b); half A and the raymarcher's image
(the probes guide, made the albedo guide on the GPU: probe_guide.py) are read back beside the sums.
Then, over later frames: half A filtered on the filter's thread (app/rendering/denoise/filter_worker.py);
on the frame its result is found, uploaded and given back its tile means into `denoised_a`
(ViewDenoise.restore_result) and judged with the raymarcher's image against the snapshot of half B (STAGE 3,
whose sums are read back the same way); and on the frame those come, the blend
(refine.blend_from_sums) of the counts and sums of the check. The judgement is as
refine.judged_blend's (a still image's), but against half B of the check's frame, the raymarcher's
image of the judging frame (independent of both halves either way), and the probes guide made
from the raymarcher's image of the check's frame (up to REFINE_RAYMARCH_FRAMES frames, the guide's
own 16) rather than marched again."""
from __future__ import annotations

from dataclasses import dataclass

from radiance_probes.gl.fence import ChunkedUpload, PendingRead, staging_buffer, start_read
from radiance_probes.methods import METHODS
from radiance_probes.rendering.denoise.filter import choose_guides
from radiance_probes.rendering.denoise.filter_worker import FilterJob
from radiance_probes.rendering.denoise.probe_guide import guide_bytes
from radiance_probes.rendering.refine.refine import blend_from_sums
from radiance_probes.viewer.frame.denoise_view import tile_means_of


@dataclass
class RefineCheck:
    """A check under way: the sums' read-back, and where it judges, half A's and the raymarcher's
    and then the filter's and the judgement's. `stage`: "sums" (waiting for the sums), "filter"
    (half A on the filter's thread), "upload" (its filtered image going up in bands), "judge"
    (the judgement's sums read back), "done"."""
    sums_read: PendingRead
    counts: tuple[int, int]
    with_ray: bool
    judgeable: bool
    judge: bool
    stage_bits: int
    half_a_read: PendingRead | None = None
    means_read: PendingRead | None = None   # half A's tile means (glsl/tile_means.comp)
    ray_read: PendingRead | None = None   # the probes guide (ProbeAlbedoGuide), packed
    guides: tuple = (None, None)      # (albedo, normal) host guides where not the probes'
    stage: str = "sums"
    sums: tuple | None = None
    judge_read: PendingRead | None = None
    upload: ChunkedUpload | None = None   # the filtered half A going up (then into denoised_a)
    result: object = None                 # its FilterResult (the raw means to give back)
    frames: int = 0                   # frames it has been under way

    def release(self) -> None:
        for r in (self.sums_read, self.half_a_read, self.means_read, self.ray_read,
                  self.judge_read, self.upload):
            if r is not None:
                r.release()
        if self.upload is not None:   # dropped while going up: its texture is its own now
            self.upload.texture.release()
            self.upload = None


def _read(session, view, key: str, source) -> PendingRead:
    """A read-back of `source` into the view's own staging buffer `key` (RefineView.staging:
    released with the view, whatever the Denoise switch does meanwhile)."""
    return start_read(session.ctx, source, view.staging, view.host, key)


def prepare_staging(session, view) -> None:
    """The view's read-back buffers for its halves' size made now and read once, so that the
    driver gives them their host memory here and not at the first check (issue 56: that
    frame's first host copy took 15.6 ms on the H200 at 1080p)."""
    halves = view.halves
    image = halves.width * halves.height * 16   # RGBA32F
    guide = guide_bytes(halves.width, halves.height)
    for key, nbytes in (("sums", halves.sums.size), ("half_a", image), ("ray", guide)):
        buf = view.staging[key] = staging_buffer(session.ctx, view.staging.get(key), nbytes)
        buf.read(size=4)


def begin_check(session, view, with_ray: bool, judgeable: bool, judge: bool,
                stage_bits: int) -> RefineCheck:
    """The check of the combine just dispatched (its reduction in halves.sums): read-backs
    started, and where it `judge`s, half B copied and half A's and the raymarcher's image read."""
    halves = view.halves
    sums_read = _read(session, view, "sums", halves.sums)
    check = RefineCheck(sums_read, halves.reduced_counts or halves.counts, with_ray, judgeable,
                        judge, stage_bits)
    if judge:
        halves.snapshot_b()
        texture = halves.half_a.texture
        # its tile means first, so that half A's fence covers their pass too
        means = session.denoise.means_on_gpu((view.method, "judge_means"), texture)
        check.means_read = _read(session, view, "means", means)
        check.half_a_read = _read(session, view, "half_a", texture)
        r = session.renderer
        names = choose_guides("auto", check.counts[0], r.probes_shown())
        if names == "probes":
            with session.denoise.parts.part("guide"):
                guide = session.denoise.albedo_guide().dispatch((view.method, "judge_guide"),
                                                                view.ray.texture)
            check.ray_read = _read(session, view, "ray", guide)
        else:
            albedo, normal, _ = r.denoise_guides(names, camera=view.camera)
            check.guides = (albedo, normal)
    return check


def advance_check(session, view, check: RefineCheck):
    """One frame's step of a check under way, never waiting: returns ("pending", None), ("sums",
    estimate sums) once the sums are in and the check does not judge, or ("judged", blend or
    None) once a judgement is done (None: the filter could not run). The sums of a judging check
    are handed out as ("sums", ...) on the frame they come too, and the check goes on."""
    check.frames += 1
    halves, denoise = view.halves, session.denoise
    key = f"{view.method}:judge"
    if check.stage == "sums":
        reads = [r for r in (check.sums_read, check.half_a_read, check.means_read, check.ray_read)
                 if r is not None]
        if not all(r.ready() for r in reads):
            return "pending", None
        with denoise.parts.part("readback", gpu=False):   # in parts over frames
            done = all(r.read_some(denoise.budget) for r in reads)
        if not done:
            return "pending", None
        check.sums = halves.sums_of(check.sums_read.out)
        if not check.judge:
            check.stage = "done"
            return "sums", check.sums
        worker = denoise.worker()
        if worker is None:
            check.stage = "done"
            return "judged", None
        half_a = check.half_a_read.out
        ray = check.ray_read.out if check.ray_read is not None else None
        albedo, normal = check.guides
        worker.submit(key, FilterJob(half_a, albedo, normal, probe_albedo=ray,
                                     signed=METHODS["guided"].signed,
                                     raw_means=tile_means_of(check.means_read, half_a)))
        check.stage = "filter"
        return "sums", check.sums
    if check.stage == "filter":
        worker = denoise.worker()
        result = None if worker is None else worker.take(key)
        if worker is not None and result is None:
            return "pending", None
        if result is None or result.rgb is None:
            if result is not None:
                denoise.note, denoise.enabled = result.note, False
            check.stage = "done"
            return "judged", None
        denoise.filter_ms += result.ms.get("filter_ms", 0.0) + result.ms.get("guide_ms", 0.0)
        h, w = result.rgb.shape[:2]
        check.upload = ChunkedUpload(denoise.rgb_texture((w, h)), result.rgb,
                                     denoise.upload_buffer)
        check.result = result
        check.stage = "upload"
    if check.stage == "upload":
        with denoise.parts.part("upload"):
            whole = check.upload.step(denoise.budget)
            if whole:
                denoise.restore_result(check.upload, check.result, halves.denoised_a)
        if not whole:
            return "pending", None
        check.upload, check.result = None, None
        with denoise.parts.part("judgement"):
            halves.dispatch_judge(view.ray, from_snapshot=True)
        check.judge_read = _read(session, view, "judge", halves.judge_sums)
        check.stage = "judge"
        return "pending", None
    if check.stage == "judge":
        if not check.judge_read.ready():
            return "pending", None
        if not check.judge_read.read_some(denoise.budget):
            return "pending", None
        judged = halves.sums_of(check.judge_read.out)
        check.stage = "done"
        n_a, n_b = check.counts
        return "judged", blend_from_sums(check.sums, judged, n_a, n_b)
    return "pending", None

