"""Convergence: `refine`'s half-images and their judgement, `render --auto`."""
