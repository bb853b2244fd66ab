"""The Python API behind `import radiance_probes`: render, Renderer, view, Image, the Jupyter widget."""
