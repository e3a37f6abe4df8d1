/* Counter-based random numbers: a hash seeds a PCG stream per pixel sample. */
#ifndef GPUGI_RNG_H
#define GPUGI_RNG_H

typedef struct {
    uint state;
} Rng;

/* Integer hash with good avalanche (lowbias32). */
inline uint Rng_hash(uint x) {
    x ^= x >> 16;
    x *= 0x7feb352dU;
    x ^= x >> 15;
    x *= 0x846ca68bU;
    x ^= x >> 16;
    return x;
}

/* A stream for (a, b, c), e.g. (pixel, sample, seed). */
inline Rng Rng_make(uint a, uint b, uint c) {
    Rng r;
    r.state = Rng_hash(a ^ Rng_hash(b ^ Rng_hash(c + 0x9e3779b9U)));
    return r;
}

/* Uniform float in [0, 1). */
inline float Rng_next(Rng *r) {
    r->state = r->state * 747796405U + 2891336453U;
    uint w = ((r->state >> ((r->state >> 28U) + 4U)) ^ r->state) * 277803737U;
    w = (w >> 22U) ^ w;
    return (float)(w >> 8) * (1.0f / 16777216.0f);
}

/* Point `index` of the R2 low-discrepancy sequence in [0, 1)^2, shifted by
 * the random offset (ox, oy) in 32-bit fixed point (exact for any index).
 * Consecutive indices fill the square evenly, so e.g. the samples of one
 * pixel stratify its area for any sample count. */
inline float2 Rng_r2(uint index, uint ox, uint oy) {
    uint x = ox + index * 3242174889U; /* 2^32 / plastic number */
    uint y = oy + index * 2447445414U; /* 2^32 / plastic number^2 */
    return (float2)((float)(x >> 8), (float)(y >> 8)) * (1.0f / 16777216.0f);
}

#endif
