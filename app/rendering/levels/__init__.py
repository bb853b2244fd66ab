"""Volumes larger than the GPU: one texture or a brick pool, mixed levels, streaming, progressive opening."""
