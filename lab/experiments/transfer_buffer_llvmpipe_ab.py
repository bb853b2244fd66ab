import sys, os, time
tree = sys.argv[1]; force = len(sys.argv) > 2; sys.path.insert(0, tree); os.chdir(tree)
import app.gl.shaders as shaders
if force:
    shaders.transfer_from_buffer = lambda ctx: True
from app.gl.context import create_headless_context
from app.render.renderer import Renderer
from app.scene import parse_scene
ctx = create_headless_context()
r = Renderer(ctx, parse_scene({"camera": {"width": 96, "height": 96}, "probes": {"grid": 8, "samples": 64}}))
r.bake(seed=1); r.render("pt", spp=2); r.render("raymarch", spp=2)
out = {}
for m in ("pt", "raymarch"):
    ts = []
    for i in range(3):
        t = time.time(); r.render(m, spp=8, seed=i); ctx.finish(); ts.append(time.time() - t)
    out[m + " s (8 spp, best of 3)"] = round(min(ts), 3)
ts = []
for i in range(3):
    t = time.time(); r.invalidate(); r.bake(seed=2); ctx.finish(); ts.append(time.time() - t)
out["bake s (best of 3)"] = round(min(ts), 3)
print("texture" if not force else "buffer", out)
