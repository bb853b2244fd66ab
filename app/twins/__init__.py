"""The NumPy twins: each module mirrors the GLSL file it is named after (twins/sh.py is
glsl/lib/sh.glsl, twins/majorant_grid.py is glsl/majorant_grid.comp; the first line of each says
which), function for function, and the tests compare the GPU's results with them."""
