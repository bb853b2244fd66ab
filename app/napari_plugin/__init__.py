"""The napari plugin (docs/napari.md): an npe2 manifest (napari.yaml, through the
`napari.manifest` entry point), the dock widget "Global illumination" (widget.py) and sample
data (samples.py). A front end: nothing else in the package imports it, and only it imports
napari and Qt (an import contract in pyproject.toml). Install with
`pip install "radiance-probes[napari]"`."""
