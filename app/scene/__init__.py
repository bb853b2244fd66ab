"""The scene model: the scene's types, transfer functions, lights, crop, camera paths and framing (imports nothing above it)."""
