"""The render methods' passes: the path tracer (and the probe and guided passes built from it), the accumulation, the raymarcher."""
