"""The radiance probes: the grid's layout, adaptive planes, the visible region, the bake, the bake's level, auto's search."""
