"""GPU time per frame of the viewer's loop (app/viewer/frame/session.py), which the interact benchmark
replays with the same numbers, per device class ("gpu", "software": llvmpipe)."""

# A frame's bake slice and samples together: a 60 Hz frame less about 2.7 ms for the display pass
# and the UI on a GPU; on llvmpipe, where one sample of a small picture takes tens of ms, the
# bake's slice and about one sample.
FRAME_BUDGET_MS = {"gpu": 14.0, "software": 65.0}
# Of which the bake's slice (Renderer.bake_step predicts how many light-grid layers or probes'
# walks fit from the slices it has timed, so the budget holds on any device).
BAKE_BUDGET_MS = {"gpu": 8.0, "software": 50.0}
