/* Shared device code of the irradiance cache: the illumination-change error,
 * per-node random numbers (rng.h's hash), and the uniform grid whose cells are
 * visited in growing rings for exact nearest searches. Positions here are
 * normalised by the host (box centre at 0, largest side 1). */
#ifndef GPUGI_CACHE_H
#define GPUGI_CACHE_H
#include "device/rng.h"

/* |n - nc|: for unit normals the chord sqrt(2 - 2 n . nc), without the
 * cancellation that formula suffers when the normals nearly agree. */
inline float Cache_chord(float3 n, float3 nc) {
    float3 d = n - nc;
    return sqrt(dot(d, d));
}

/* Error between a point (x, n) and a reference (c, nc) [WZPB09]:
 * alpha |x - c| + sqrt(2 - 2 n . nc). */
inline float Cache_eps(float alpha, float3 x, float3 n, float3 c, float3 nc) {
    float3 d = x - c;
    return alpha * sqrt(dot(d, d)) + Cache_chord(n, nc);
}

/* Whether (e, id) comes before (best_e, best_id): smaller error, then index. */
inline bool Cache_before(float e, int id, float best_e, int best_id) {
    return e < best_e || (e == best_e && id < best_id);
}

/* Errors up to Cache_tie_window(e_min) tie with the smallest one e_min and
 * the lowest index among them wins. Symmetric configurations (a centre
 * midway between two points) give errors equal but for float rounding; a
 * window far wider than that rounding keeps the choice the same at any
 * scene scale and on any device. */
#define CACHE_TIE 1e-6f

inline float Cache_tie_window(float e_min) {
    return e_min + CACHE_TIE * (1.0f + e_min);
}

/* Uniform float in [0, 1) for the triple (a, b, c). */
inline float Cache_random(uint a, uint b, uint c) {
    uint h = Rng_hash(a ^ Rng_hash(b ^ Rng_hash(c + 0x9e3779b9U)));
    return (float)(h >> 8) * (1.0f / 16777216.0f);
}

/* Uniform grid: origin.xyz and cell size origin.w; dims.xyz cells. Items of
 * cell k are items[start[k] .. end[k]) (gpu_core/gi/cache/grid.py). */
#define CACHE_GRID_PARAMS                                                    \
    const float4 grid_origin, const int4 grid_dims,                          \
        const __global int *grid_start, const __global int *grid_end,        \
        const __global int *grid_items

/* The cell holding x, clamped into the grid. */
inline int3 Cache_grid_cell(float3 x, float4 origin, int4 dims) {
    float3 f = floor((x - origin.xyz) / origin.w);
    f = clamp(f, (float3)(0.0f), convert_float3(dims.xyz - 1));
    return convert_int3(f);
}

/* Cells at Chebyshev distance exactly r from c, inside the grid. */
typedef struct {
    int3 c;
    int r;
    int3 lo, hi;
    int x, y, z;
} CacheRing;

inline void CacheRing_begin(CacheRing *g, int3 c, int r, int4 dims) {
    g->c = c;
    g->r = r;
    g->lo = max(c - r, (int3)(0));
    g->hi = min(c + r, dims.xyz - 1);
    g->x = g->lo.x - 1;
    g->y = g->lo.y;
    g->z = g->lo.z;
}

/* Linear index of the ring's next cell, -1 when the ring is done. Rows
 * strictly inside the ring's cube only have their two end cells visited. */
inline int CacheRing_next(CacheRing *g, int4 dims) {
    while (true) {
        g->x++;
        if (g->x > g->hi.x) {
            g->x = g->lo.x;
            g->y++;
            if (g->y > g->hi.y) {
                g->y = g->lo.y;
                g->z++;
                if (g->z > g->hi.z) return -1;
            }
        }
        bool face = abs(g->y - g->c.y) == g->r || abs(g->z - g->c.z) == g->r;
        if (!face && abs(g->x - g->c.x) < g->r) {
            g->x = g->c.x + g->r; /* jump over the inside of this row */
            if (g->x > g->hi.x) continue;
        }
        return (g->z * dims.y + g->y) * dims.x + g->x;
    }
}

/* Lower bound on the distance from x to every cell outside rings 0..r
 * around c; FLT_MAX when no cell is left. */
inline float Cache_ring_bound(float3 x, int3 c, int r, float4 origin, int4 dims) {
    float h = origin.w;
    float bound = FLT_MAX;
    if (c.x - r > 0) bound = fmin(bound, x.x - (origin.x + (float)(c.x - r) * h));
    if (c.x + r < dims.x - 1) bound = fmin(bound, origin.x + (float)(c.x + r + 1) * h - x.x);
    if (c.y - r > 0) bound = fmin(bound, x.y - (origin.y + (float)(c.y - r) * h));
    if (c.y + r < dims.y - 1) bound = fmin(bound, origin.y + (float)(c.y + r + 1) * h - x.y);
    if (c.z - r > 0) bound = fmin(bound, x.z - (origin.z + (float)(c.z - r) * h));
    if (c.z + r < dims.z - 1) bound = fmin(bound, origin.z + (float)(c.z + r + 1) * h - x.z);
    return bound == FLT_MAX ? FLT_MAX : fmax(bound, 0.0f);
}

/* Rings needed to cover the whole grid from c. */
inline int Cache_ring_count(int3 c, int4 dims) {
    int3 far = max(c, dims.xyz - 1 - c);
    return max(max(far.x, far.y), far.z) + 1;
}

#endif
