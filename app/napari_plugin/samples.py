"""Sample data for napari's File > Open Sample menu (npe2 sample-data contributions): the built-in
cloud, a small CT-like head in Hounsfield units, and cells in two channels (nuclei, membranes).
Each returns napari's layer-data tuples (data, layer keywords, "image")."""
from __future__ import annotations

import numpy as np

CT_SIZE = 96
# The built-in head's densities (app/io/volume.py builtin_head: air 0, ventricles 0.1, fat 0.15,
# skin 0.3, brain 0.55-0.75, skull 1) and the Hounsfield units of those tissues (adult CT).
HEAD_DENSITY = (0.0, 0.1, 0.15, 0.3, 0.55, 0.75, 1.0)
HEAD_HU = (-1000.0, 5.0, -100.0, 40.0, 30.0, 45.0, 1200.0)


def cloud():
    from radiance_probes.io.builtin_volumes import builtin_cloud
    data = builtin_cloud((96, 96, 96))
    return [(data, {"name": "cloud", "colormap": "magma", "contrast_limits": (0.0, 1.0),
                    "rendering": "translucent"}, "image")]


def ct_head_hounsfield(size: int = CT_SIZE) -> np.ndarray:
    """[z, y, x] int16 Hounsfield units: the built-in head's tissues at their HU (HEAD_HU)."""
    from radiance_probes.io.builtin_volumes import builtin_head
    d = builtin_head((size, size, size))
    return np.round(np.interp(d, HEAD_DENSITY, HEAD_HU)).astype(np.int16)


def ct_head():
    return [(ct_head_hounsfield(), {"name": "CT head (HU)", "colormap": "gray",
                                    "contrast_limits": (-200.0, 1500.0), "scale": (2.0, 2.0, 2.0),
                                    "rendering": "translucent"}, "image")]


def cells(size: int = 80, seed: int = 3) -> list:
    """Two channels of a cell-like volume: nuclei (filled ellipsoids) and membranes (shells
    around them), uint16 with a little noise."""
    rng = np.random.default_rng(seed)
    z, y, x = np.meshgrid(*(np.linspace(-1.0, 1.0, size),) * 3, indexing="ij")
    nuclei = np.zeros((size,) * 3, np.float32)
    membranes = np.zeros((size,) * 3, np.float32)
    for _ in range(9):
        c = rng.uniform(-0.55, 0.55, 3)
        r = rng.uniform(0.18, 0.3)
        dist = np.sqrt(((z - c[0]) / (0.8 * r)) ** 2 + ((y - c[1]) / r) ** 2
                       + ((x - c[2]) / (1.1 * r)) ** 2)
        nuclei = np.maximum(nuclei, np.clip(1.6 - 2.0 * dist / 0.55, 0.0, 1.0))
        membranes = np.maximum(membranes, np.exp(-((dist - 1.0) / 0.08) ** 2))
    noise = rng.normal(0.0, 0.02, (2, size, size, size))
    to_u16 = lambda a: np.clip(a * 3000 + 150, 0, 65535).astype(np.uint16)   # noqa: E731
    return [(to_u16(nuclei + noise[0]), {"name": "nuclei", "colormap": "cyan",
                                         "contrast_limits": (300.0, 3200.0),
                                         "blending": "additive"}, "image"),
            (to_u16(membranes + noise[1]), {"name": "membranes", "colormap": "magenta", "opacity": 0.12,
                                            "contrast_limits": (300.0, 3200.0),
                                            "blending": "additive"}, "image")]
