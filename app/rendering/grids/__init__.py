"""The cached grids the renderers read: the sun's light grid, the majorant grid, the opacity-gradient grid."""
