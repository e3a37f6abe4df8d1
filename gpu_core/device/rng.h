/* Counter-based random numbers: a hash seeds a PCG stream per pixel sample;
 * low-discrepancy sequences for the dimensions that gain from them. */
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

/* x with its 32 bits in reverse order: the compiler's builtin where it has
 * one (a byte swap and three steps on a CPU, one instruction on some),
 * else five swap steps. A simulator's interpreter lacks the builtin's LLVM
 * intrinsic, which its compiler also makes of the swap steps: there each
 * byte is reversed on its own (three multiplies, Anderson's bit hacks). */
inline uint Rng_reverse(uint x) {
#if defined(GPUGI_SIMULATOR)
    uint r = 0u;
    for (int b = 0; b < 4; ++b) {
        ulong byte = (x >> (8 * b)) & 0xffU;
        uint flipped = (uint)((((byte * 0x80200802UL) & 0x0884422110UL) * 0x0101010101UL) >> 32) & 0xffU;
        r |= flipped << (24 - 8 * b);
    }
    return r;
#elif defined(__has_builtin) && __has_builtin(__builtin_bitreverse32)
    return __builtin_bitreverse32(x);
#else
    x = ((x >> 1) & 0x55555555U) | ((x & 0x55555555U) << 1);
    x = ((x >> 2) & 0x33333333U) | ((x & 0x33333333U) << 2);
    x = ((x >> 4) & 0x0f0f0f0fU) | ((x & 0x0f0f0f0fU) << 4);
    x = ((x >> 8) & 0x00ff00ffU) | ((x & 0x00ff00ffU) << 8);
    return (x >> 16) | (x << 16);
#endif
}

/* The Laine-Karras permutation: each bit of x flipped by a hash of the
 * seed and the bits below it. */
inline uint Rng_laine_karras(uint x, uint seed) {
    x += seed;
    x ^= x * 0x6c50b47cU;
    x ^= x * 0xb82f1e52U;
    x ^= x * 0xc7afe638U;
    x ^= x * 0x8d22f6e6U;
    return x;
}

/* Owen scrambling of a 32-bit fraction, hashed [Burley 2020, "Practical
 * hash-based Owen scrambling"]: the Laine-Karras permutation of its
 * reversed bits, so that each bit is flipped by a hash of the bits above
 * it. Applied to an index instead, it shuffles a sequence in aligned
 * blocks of powers of two, so any aligned 2^m points stay well spread. */
inline uint Rng_owen(uint x, uint seed) { return Rng_reverse(Rng_laine_karras(Rng_reverse(x), seed)); }

/* Point `index` of the first two Sobol dimensions (a (0, 2)-sequence:
 * every 2^m consecutive points from a multiple of 2^m put one point in
 * each of 2^m equal cells, of any shape), shuffled and Owen-scrambled by
 * `seed`, in [0, 1)^2. Sequences of different seeds are independent. The
 * first dimension is the index's bits reversed; the second, reversed,
 * has bit j the parity of the index's bits k with j a subset of k (Pascal's
 * triangle mod 2), a superset transform in five shift-xor steps. */
inline float2 Rng_sobol2(uint index, uint seed) {
    uint i = Rng_owen(index, Rng_hash(seed));
    uint p = i;
    p ^= (p >> 1) & 0x55555555U;
    p ^= (p >> 2) & 0x33333333U;
    p ^= (p >> 4) & 0x0f0f0f0fU;
    p ^= (p >> 8) & 0x00ff00ffU;
    p ^= (p >> 16) & 0x0000ffffU;
    /* Owen scrambling of each: Rng_owen(Rng_reverse(v), s) = Rng_reverse(Rng_laine_karras(v, s)) */
    uint x = Rng_reverse(Rng_laine_karras(i, Rng_hash(seed ^ 0x5bd1e995U)));
    uint y = Rng_reverse(Rng_laine_karras(p, Rng_hash(seed ^ 0x27d4eb2fU)));
    return (float2)((float)(x >> 8), (float)(y >> 8)) * (1.0f / 16777216.0f);
}

#endif
