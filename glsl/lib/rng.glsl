// Random numbers: PCG-RXS-M-XS 32 (O'Neill; the GPU form of Jarzynski & Olano 2020).
// A stream is keyed by (pixel or probe, sample index, seed) through chained hashes, so an image is
// reproducible for a given seed and independent of how the work is split into passes.
// NumPy twin: app/twins/rng.py.

uint pcg_hash(uint v)
{
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

uint rng_seed(uint key, uint sample_index, uint seed)
{
    return pcg_hash(key ^ pcg_hash(sample_index ^ pcg_hash(seed)));
}

uint rng_next_uint(inout uint state)
{
    state = state * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Uniform in [0, 1): the top 24 bits, so every value is exact in float32 and 1 is never returned.
float rng_next(inout uint state)
{
    return float(rng_next_uint(state) >> 8u) * (1.0 / 16777216.0);
}
