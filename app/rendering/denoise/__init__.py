"""The denoiser over Open Image Denoise, its guides, and the kept raw tile means."""
