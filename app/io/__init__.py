"""Loaders: volume files and folders, DICOM, bricks, environment maps, and the scene file itself."""
