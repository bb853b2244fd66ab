"""Writes assets/colormaps.json: 256 RGB entries per preset, sampled from matplotlib's tables.

Run once (matplotlib is not a runtime dependency): python assets/make_colormaps.py
plasma, viridis, inferno and magma are van der Walt and Smith's; coolwarm is Moreland's diverging
map; turbo is Google's rainbow; grey is linear.
"""
import json
from pathlib import Path

import matplotlib
import numpy as np

NAMES = {"plasma": "plasma", "viridis": "viridis", "inferno": "inferno", "magma": "magma",
         "coolwarm": "coolwarm", "turbo": "turbo", "grey": "gray"}

out = {}
x = np.linspace(0.0, 1.0, 256)
for ours, theirs in NAMES.items():
    rgb = matplotlib.colormaps[theirs](x)[:, :3]
    out[ours] = [[round(float(c), 6) for c in row] for row in rgb]
path = Path(__file__).with_name("colormaps.json")
path.write_text(json.dumps(out, separators=(",", ":")))
print(f"wrote {path}")
