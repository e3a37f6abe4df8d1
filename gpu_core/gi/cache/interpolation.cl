/* Irradiance at shading points from the cache samples with Ward's weights
 * w_j = 1 / (|x - x_j| / R_j + sqrt(2 - 2 n . n_j)) over the samples within
 * a R_j of x that face the same way and are not in front of x [WZPB09, Ward
 * 1988]. Candidates come from a hash grid with one level per power-of-two
 * radius: a sample is listed in every cell its coverage sphere's box meets
 * on the level whose cells are at least its radius across (at most 3 per
 * axis: CACHE_SLOTS cells, from the host), so a query visits one cell, its
 * own, on each level in use. Points no sample covers take the nearest
 * sample with a compatible normal (carried by its gradient from the edge
 * of its coverage), else the nearest one (gpu_core/gi/cache/interpolation.py). */
#include "device/launch.h"
#include "gi/cache/cache.h"

/* Cell sizes 2, 1, 1/2, ... 2^-16 (normalised units): the finest cells stay
 * far wider than float rounding of the coordinates. */
#define CACHE_LEVELS 18
#define CACHE_MIN_COS 0.01f /* samples with n . n_j at or below this are rejected */

/* Level of a sample of coverage radius r <= 2: the finest one whose cells
 * (2^(1-g) across) are still at least r. */
inline int Cache_level(float r) {
    float f = floor(log2(2.0f / fmax(r, 1e-30f)));
    int g = (int)clamp(f, 0.0f, (float)(CACHE_LEVELS - 1));
    while (g > 0 && ldexp(2.0f, -g) < r) g--;
    return g;
}

/* Cell of x on level g. */
inline int4 Cache_level_cell(float3 x, int g) {
    float3 f = floor((x + 1.0f) / ldexp(2.0f, -g));
    return (int4)(convert_int3(f), g);
}

/* Hash-table slot of a cell. */
inline uint Cache_bucket(int4 cell, uint mask) {
    uint h = (uint)cell.x * 73856093U ^ (uint)cell.y * 19349663U ^ (uint)cell.z * 83492791U;
    return Rng_hash(h ^ (uint)cell.w * 2654435761U) & mask;
}

/* Samples into the cache's frame: position (p - centre) / extent with w the
 * coverage radius a R_j, R_j / extent, bounded (a zero, negative or NaN
 * R_j takes the smallest radius, an infinite one the largest), and the
 * translational gradient's rows (dE/dx, dE/dy, dE/dz, rgb, in scene units)
 * per frame unit, each channel's scaled down to change E_j by at most
 * CACHE_GRADIENT_LIMIT of its value over R_j (Krivanek et al. 2006 bound it
 * beside neighbour clamping, whose R_j it takes). */
__kernel void Cache_prepare_samples(const __global float4 *spos, const __global float *srad,
                                    const __global float4 *sirr, const __global float4 *sgrad, const int m,
                                    const float4 centre_high, const float4 centre_low, const float extent,
                                    const float a, __global float4 *out_pos, __global float *out_rad,
                                    __global float4 *out_grad) {
    int j = Launch_global_id();
    if (j >= m) return;
    float r = srad[j] / extent;
    r = isnan(r) ? CACHE_MIN_R : clamp(r, CACHE_MIN_R, CACHE_MAX_R);
    float3 d = (spos[j].xyz - centre_high.xyz) - centre_low.xyz;
    out_pos[j] = (float4)(d / extent, fmin(a * r, CACHE_MAX_COVER));
    out_rad[j] = r;
    float4 gx = sgrad[3 * j], gy = sgrad[3 * j + 1], gz = sgrad[3 * j + 2];
    float3 size = sqrt(gx.xyz * gx.xyz + gy.xyz * gy.xyz + gz.xyz * gz.xyz) * (r * extent);
    float3 scale = fmin((float3)(1.0f), CACHE_GRADIENT_LIMIT * sirr[j].xyz / fmax(size, 1e-30f)) * extent;
    out_grad[3 * j] = (float4)(gx.xyz * scale, 0.0f);
    out_grad[3 * j + 1] = (float4)(gy.xyz * scale, 0.0f);
    out_grad[3 * j + 2] = (float4)(gz.xyz * scale, 0.0f);
}

/* The cells of each sample's level that the box of its coverage sphere
 * meets, in its slots (CACHE_SLOTS j + t) with their hash buckets; the slots
 * left over get the bucket mask + 1, past every real one. And the set of
 * levels in use. */
__kernel void Cache_sample_cells(const __global float4 *spos, const int m, const uint mask,
                                 __global int4 *cells, __global uint *keys,
                                 volatile __global uint *levels) {
    int j = Launch_global_id();
    if (j >= m) return;
    float4 s = spos[j];
    int g = Cache_level(s.w);
    int4 lo = Cache_level_cell(s.xyz - s.w, g), hi = Cache_level_cell(s.xyz + s.w, g);
    for (int t = 0; t < CACHE_SLOTS; ++t) {
        int4 cell = lo + (int4)(t % 3, t / 3 % 3, t / 9, 0);
        bool inside = cell.x <= hi.x && cell.y <= hi.y && cell.z <= hi.z;
        cells[CACHE_SLOTS * j + t] = cell;
        keys[CACHE_SLOTS * j + t] = inside ? Cache_bucket(cell, mask) : mask + 1U;
    }
    atomic_or(levels, 1U << g);
}

/* Each bucket's entries side by side, in the order of the slots grouped by
 * bucket (bucket_items): the slot's cell and its sample's position and
 * coverage radius, so a lookup scans its bucket's candidates in a row and
 * reads a sample's other data only where it covers the point. */
__kernel void Cache_bucket_entries(const __global int *bucket_items, const int count, const __global int4 *cells,
                                   const __global float4 *spos, __global int4 *entry_cell,
                                   __global float4 *entry_pos) {
    int k = Launch_global_id();
    if (k >= count) return;
    int slot = bucket_items[k];
    entry_cell[k] = cells[slot];
    entry_pos[k] = spos[slot / CACHE_SLOTS];
}

/* The hash grid of coverage spheres: the slots of each bucket
 * (bucket_items[bucket_start[b] .. bucket_end[b])) and their entries
 * (Cache_bucket_entries). */
#define CACHE_HASH_PARAMS                                                    \
    const __global float4 *snrm, const __global float4 *sirr, const __global float4 *sgrad,            \
        const __global float *srad, const __global int4 *entry_cell, const __global float4 *entry_pos, \
        const __global int *bucket_start, const __global int *bucket_end, const __global int *bucket_items, \
        const uint mask, const uint levels

/* Sample j's irradiance carried to x by its bounded gradient (rows per
 * frame unit: Cache_prepare_samples) over the offset d, never negative. */
inline float3 Cache_extrapolated(const __global float4 *sirr, const __global float4 *sgrad, int j, float3 d) {
    const __global float4 *g = sgrad + 3 * j;
    return fmax(sirr[j].xyz + d.x * g[0].xyz + d.y * g[1].xyz + d.z * g[2].xyz, (float3)(0.0f));
}

/* Ward's weighted mean over the samples covering x (normal nx) that face
 * its way and do not lie in front of it, each carried to x by its gradient;
 * the summed weight goes to *wsum (0 when none covers it). A running mean
 * cannot overflow, and samples of equal irradiance and no gradient leave it
 * exactly at that value. */
inline float3 Cache_covering_mean(CACHE_HASH_PARAMS, float3 x, float3 nx, float behind, float *wsum) {
    float3 mean = (float3)(0.0f);
    *wsum = 0.0f;
    for (int g = 0; g < CACHE_LEVELS; ++g) {
        if (!((levels >> g) & 1U)) continue;
        int4 cell = Cache_level_cell(x, g);
        uint b = Cache_bucket(cell, mask);
        for (int k = bucket_start[b]; k < bucket_end[b]; ++k) {
            int4 cs = entry_cell[k];
            if (cs.x != cell.x || cs.y != cell.y || cs.z != cell.z || cs.w != g) continue;
            float4 sj = entry_pos[k];
            float3 d = x - sj.xyz;
            float dist = sqrt(dot(d, d));
            if (dist >= sj.w) continue;
            int j = bucket_items[k] / CACHE_SLOTS;
            float3 nj = snrm[j].xyz;
            float cosn = dot(nx, nj);
            float rj = srad[j];
            if (cosn <= CACHE_MIN_COS || dot(d, nx + nj) < -behind * rj) continue;
            float w = 1.0f / fmax(dist / rj + Cache_chord(nx, nj), 1e-6f);
            *wsum += w;
            /* the first sample is taken as it is (w / w need not round to 1) */
            float3 e = Cache_extrapolated(sirr, sgrad, j, d);
            mean = *wsum == w ? e : mean + (w / *wsum) * (e - mean);
        }
    }
    return mean;
}

/* The sample nearest x with a compatible normal, else the nearest one
 * (ties within the window: lower index), in two passes as Cache_assign;
 * -1 when there are no samples. *compatible says which it is. */
inline int Cache_nearest_sample(const __global float4 *spos, const __global float4 *snrm, CACHE_GRID_PARAMS,
                                const int m, float3 x, float3 nx, bool *compatible) {
    float d_ok = FLT_MAX, d_any = FLT_MAX;
    int3 c = Cache_grid_cell(x, grid_origin, grid_dims);
    int rings = m > 0 ? Cache_ring_count(c, grid_dims) : 0;
    int used = rings;
    for (int r = 0; r < rings; ++r) {
        CacheRing ring;
        CacheRing_begin(&ring, c, r, grid_dims);
        int cell;
        while ((cell = CacheRing_next(&ring, grid_dims)) >= 0) {
            for (int k = grid_start[cell]; k < grid_end[cell]; ++k) {
                int j = grid_items[k];
                float3 d = x - spos[j].xyz;
                float dist = sqrt(dot(d, d));
                d_any = fmin(d_any, dist);
                if (dot(nx, snrm[j].xyz) > CACHE_MIN_COS) d_ok = fmin(d_ok, dist);
            }
        }
        float bound = Cache_ring_bound(x, c, r, grid_origin, grid_dims);
        if (bound == FLT_MAX || (d_ok < FLT_MAX && bound * (1.0f - 1e-5f) > Cache_tie_window(d_ok))) {
            used = r + 1;
            break;
        }
    }
    *compatible = d_ok < FLT_MAX;
    float window = Cache_tie_window(*compatible ? d_ok : d_any);
    int best_ok = INT_MAX, best_any = INT_MAX;
    for (int r = 0; r < used; ++r) {
        CacheRing ring;
        CacheRing_begin(&ring, c, r, grid_dims);
        int cell;
        while ((cell = CacheRing_next(&ring, grid_dims)) >= 0) {
            for (int k = grid_start[cell]; k < grid_end[cell]; ++k) {
                int j = grid_items[k];
                float3 d = x - spos[j].xyz;
                if (sqrt(dot(d, d)) > window) continue;
                best_any = min(best_any, j);
                if (dot(nx, snrm[j].xyz) > CACHE_MIN_COS) best_ok = min(best_ok, j);
            }
        }
    }
    int pick = *compatible ? best_ok : best_any;
    return pick == INT_MAX ? -1 : pick;
}

/* Interpolated irradiance at each point. flag: 1 covered, 2 nearest
 * compatible sample, 3 nearest sample, 0 no samples at all.
 * spos: xyz, w = coverage radius a R_j; srad: R_j (both normalised). */
__kernel void Cache_interpolate(const __global float4 *pos, const __global float4 *nrm, const int n,
                                const __global float4 *spos, CACHE_HASH_PARAMS, CACHE_GRID_PARAMS, const int m,
                                const float behind,
                                __global float4 *out, __global int *flag) {
    int i = Launch_global_id();
    if (i >= n) return;
    float3 x = pos[i].xyz, nx = nrm[i].xyz;
    float wsum;
    float3 mean = Cache_covering_mean(snrm, sirr, sgrad, srad, entry_cell, entry_pos, bucket_start, bucket_end,
                                      bucket_items, mask, levels, x, nx, behind, &wsum);
    if (wsum > 0.0f) {
        out[i] = (float4)(mean, 0.0f);
        flag[i] = 1;
        return;
    }
    bool compatible;
    int pick = Cache_nearest_sample(spos, snrm, grid_origin, grid_dims, grid_start, grid_end, grid_items, m, x, nx,
                                    &compatible);
    float3 e = (float3)(0.0f);
    if (pick >= 0 && compatible) {
        /* carried by its gradient as if from the edge of its coverage */
        float3 d = x - spos[pick].xyz;
        float len = length(d), cover = spos[pick].w;
        e = Cache_extrapolated(sirr, sgrad, pick, len > cover ? d * (cover / len) : d);
    } else if (pick >= 0) {
        e = sirr[pick].xyz;
    }
    out[i] = (float4)(e, 0.0f);
    flag[i] = pick < 0 ? 0 : (compatible ? 2 : 3);
}

/* Flag 0..3 as a one-hot int4, for the host's count of each. */
__kernel void Cache_flag_one_hot(const __global int *flag, const int n, __global int4 *out) {
    int i = Launch_global_id();
    if (i < n) out[i] = (int4)(flag[i] == 0, flag[i] == 1, flag[i] == 2, flag[i] == 3);
}

/* 1 where a point is not covered by any sample (flag other than 1). */
__kernel void Cache_uncovered(const __global int *flag, const int n, __global int *out) {
    int i = Launch_global_id();
    if (i < n) out[i] = flag[i] != 1;
}
