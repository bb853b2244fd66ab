"""Movies: a movie's frames with the probes baked once, and the MP4/GIF/PNG writer."""
