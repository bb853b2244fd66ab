"""``radiance-probes bench``: speed against error for every method, written as JSON and Markdown."""
