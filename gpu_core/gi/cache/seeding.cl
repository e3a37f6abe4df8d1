/* Adaptive seeding over a screen-space quadtree [WZPB09]: each node's mean
 * position and normal, the mean error of its shading points to that mean,
 * and the seed budget handed down in proportion to error. Levels are dense
 * row-major grids of nodes; level L is the leaf level (gpu_core/gi/cache/seeding.py). */
#include "device/launch.h"
#include "gi/cache/cache.h"

/* Mean position and unit mean normal of a node (normal 0 when the normals
 * cancel out). */
inline void Cache_node_mean(float4 psum, float4 nsum, int count, float3 *x, float3 *n) {
    *x = count > 0 ? psum.xyz / (float)count : (float3)(0.0f);
    float len = sqrt(dot(nsum.xyz, nsum.xyz));
    *n = len > 1e-12f ? nsum.xyz / len : (float3)(0.0f);
}

/* keys[i] = leaf cell of the pixel of shading point i. */
__kernel void Cache_leaf_keys(const __global int2 *pixels, const int n, const int shift,
                              const int leaf_w, __global uint *keys) {
    int i = Launch_global_id();
    if (i >= n) return;
    int2 p = pixels[i];
    keys[i] = (uint)((p.y >> shift) * leaf_w + (p.x >> shift));
}

/* A node's mean position and unit mean normal into `means` (two float4 a
 * node: every level's nodes in one array, the level's first at `at`). */
inline void Cache_store_mean(float4 psum, float4 nsum, int count, __global float4 *means, int at) {
    float3 x, n;
    Cache_node_mean(psum, nsum, count, &x, &n);
    means[2 * at] = (float4)(x, 0.0f);
    means[2 * at + 1] = (float4)(n, 0.0f);
}

/* Sums of positions and normals and the count of each leaf cell's points,
 * and its means (the leaf level's first node at `first`). */
__kernel void Cache_leaf_sums(const __global int *start, const __global int *end,
                              const __global int *order, const __global float4 *pos,
                              const __global float4 *nrm, const int cells,
                              __global float4 *psum, __global float4 *nsum, __global int *count,
                              __global float4 *means, const int first) {
    int k = Launch_global_id();
    if (k >= cells) return;
    float4 ps = (float4)(0.0f), ns = (float4)(0.0f);
    for (int j = start[k]; j < end[k]; ++j) {
        int i = order[j];
        ps += (float4)(pos[i].xyz, 0.0f);
        ns += (float4)(nrm[i].xyz, 0.0f);
    }
    psum[k] = ps;
    nsum[k] = ns;
    count[k] = end[k] - start[k];
    Cache_store_mean(ps, ns, end[k] - start[k], means, first + k);
}

/* A parent node's sums from its (up to four) children one level below, and
 * its means (the parent level's first node at `first`). */
__kernel void Cache_pyramid_sums(const __global float4 *child_psum, const __global float4 *child_nsum,
                                 const __global int *child_count, const int2 child_dims,
                                 __global float4 *psum, __global float4 *nsum, __global int *count,
                                 const int2 dims, __global float4 *means, const int first) {
    int k = Launch_global_id();
    if (k >= dims.x * dims.y) return;
    int x = k % dims.x, y = k / dims.x;
    float4 ps = (float4)(0.0f), ns = (float4)(0.0f);
    int c = 0;
    for (int dy = 0; dy < 2; ++dy) {
        for (int dx = 0; dx < 2; ++dx) {
            int cx = 2 * x + dx, cy = 2 * y + dy;
            if (cx >= child_dims.x || cy >= child_dims.y) continue;
            int ck = cy * child_dims.x + cx;
            ps += child_psum[ck];
            ns += child_nsum[ck];
            c += child_count[ck];
        }
    }
    psum[k] = ps;
    nsum[k] = ns;
    count[k] = c;
    Cache_store_mean(ps, ns, c, means, first + k);
}

/* Per leaf cell: the sum of its points' errors to the mean of each of its
 * ancestors, itself included; row `up` (of `cells` values) holds the one
 * `up` levels higher, rows 0 to `depth`. Levels are root first in `means`,
 * each (leaf_dims >> up, rounded up) nodes. */
__kernel void Cache_leaf_errors(const __global int *start, const __global int *end,
                                const __global int *order, const __global float4 *pos,
                                const __global float4 *nrm, const int2 leaf_dims, const int depth,
                                const __global float4 *means, const float alpha, __global float *err) {
    int k = Launch_global_id();
    int cells = leaf_dims.x * leaf_dims.y;
    if (k >= cells) return;
    int kx = k % leaf_dims.x, ky = k / leaf_dims.x;
    int first = 0; /* the level's first node in means */
    for (int up = depth; up >= 0; --up) {
        int2 dims = (leaf_dims + (1 << up) - 1) >> up;
        int a = first + (ky >> up) * dims.x + (kx >> up);
        float3 mx = means[2 * a].xyz, mn = means[2 * a + 1].xyz;
        float e = 0.0f;
        for (int j = start[k]; j < end[k]; ++j) {
            int i = order[j];
            e += Cache_eps(alpha, pos[i].xyz, nrm[i].xyz, mx, mn);
        }
        err[up * cells + k] = e;
        first += dims.x * dims.y;
    }
}

/* A parent level's error rows from its children's: row r of a node (its
 * points' errors to the mean of its ancestor r levels up) is the sum of row
 * r + 1 of its (up to four) children; `rows` rows of dims.x * dims.y. */
__kernel void Cache_pyramid_errors(const __global float *child_err, const int2 child_dims,
                                   __global float *err, const int2 dims, const int rows) {
    int k = Launch_global_id();
    int cells = dims.x * dims.y, child_cells = child_dims.x * child_dims.y;
    if (k >= cells) return;
    int x = k % dims.x, y = k / dims.x;
    for (int r = 0; r < rows; ++r) {
        float e = 0.0f;
        for (int dy = 0; dy < 2; ++dy) {
            for (int dx = 0; dx < 2; ++dx) {
                int cx = 2 * x + dx, cy = 2 * y + dy;
                if (cx < child_dims.x && cy < child_dims.y) e += child_err[(r + 1) * child_cells + cy * child_dims.x + cx];
            }
        }
        err[r * cells + k] = e;
    }
}

/* Split a node's seed budget among its children in proportion to their
 * error (the sum of their points' errors: mean error times point count),
 * never more than a child's point count. Capped children take their count
 * and the rest is shared again (water filling); the shares are rounded by
 * systematic sampling with one random offset per node, so each child gets
 * the floor or the ceiling of its share and the total is exact. */
__kernel void Cache_distribute(const __global int *budget, const int2 dims,
                               const __global int *child_count, const __global float *child_err,
                               const int2 child_dims, __global int *child_budget,
                               const uint seed, const int level) {
    int k = Launch_global_id();
    if (k >= dims.x * dims.y) return;
    int x = k % dims.x, y = k / dims.x;
    int id[4], cap[4], got[4];
    float w[4];
    bool open[4];
    int m = 0;
    for (int dy = 0; dy < 2; ++dy) {
        for (int dx = 0; dx < 2; ++dx) {
            int cx = 2 * x + dx, cy = 2 * y + dy;
            if (cx >= child_dims.x || cy >= child_dims.y) continue;
            int ck = cy * child_dims.x + cx;
            id[m] = ck;
            cap[m] = child_count[ck];
            w[m] = child_err[ck];
            got[m] = 0;
            open[m] = cap[m] > 0;
            m++;
        }
    }
    int left = budget[k];
    /* water filling: children whose share reaches their count are capped */
    for (int round = 0; round < 4 && left > 0; ++round) {
        float total = 0.0f;
        for (int c = 0; c < m; ++c) total += open[c] ? w[c] : 0.0f;
        if (!(total > 0.0f)) { /* no error left to share by: share by count */
            total = 0.0f;
            for (int c = 0; c < m; ++c) {
                w[c] = (float)cap[c];
                total += open[c] ? w[c] : 0.0f;
            }
        }
        bool capped = false;
        for (int c = 0; c < m; ++c) {
            if (open[c] && (float)left * w[c] >= (float)cap[c] * total) {
                got[c] = cap[c];
                open[c] = false;
                capped = true;
            }
        }
        if (!capped) break;
        left = budget[k];
        for (int c = 0; c < m; ++c) left -= got[c];
    }
    /* systematic rounding of the open children's shares */
    if (left > 0) {
        float total = 0.0f;
        int last = -1;
        for (int c = 0; c < m; ++c) {
            if (open[c]) {
                total += w[c];
                last = c;
            }
        }
        float u = Cache_random(seed, (uint)level, (uint)k);
        float cum = 0.0f;
        int before = 0;
        for (int c = 0; c < m; ++c) {
            if (!open[c]) continue;
            cum += w[c];
            int upto = c == last ? left : min(left, (int)floor((float)left * (cum / total) + u));
            got[c] = clamp(upto - before, 0, cap[c]);
            before = max(before, upto);
        }
        /* a share clamped by rounding goes to children with room */
        int given = 0;
        for (int c = 0; c < m; ++c) given += open[c] ? got[c] : 0;
        for (int c = 0; c < m && given < left; ++c) {
            int more = open[c] ? min(left - given, cap[c] - got[c]) : 0;
            got[c] += more;
            given += more;
        }
    }
    for (int c = 0; c < m; ++c) child_budget[id[c]] = got[c];
}

/* Each leaf cell's `budget` seeds: its points with the smallest error to the
 * cell mean (ties by index), written from `offset` on. */
__kernel void Cache_leaf_seeds(const __global int *start, const __global int *end,
                               const __global int *order, const __global float4 *pos,
                               const __global float4 *nrm, const __global float4 *psum,
                               const __global float4 *nsum, const __global int *count,
                               const __global int *budget, const __global int *offset,
                               const int cells, const float alpha, __global int *seeds) {
    int k = Launch_global_id();
    if (k >= cells || budget[k] == 0) return;
    float3 mx, mn;
    Cache_node_mean(psum[k], nsum[k], count[k], &mx, &mn);
    float last_e = -1.0f;
    int last_i = -1;
    for (int s = 0; s < budget[k]; ++s) {
        float best_e = FLT_MAX;
        int best_i = INT_MAX;
        for (int j = start[k]; j < end[k]; ++j) {
            int i = order[j];
            float e = Cache_eps(alpha, pos[i].xyz, nrm[i].xyz, mx, mn);
            if (Cache_before(last_e, last_i, e, i) && Cache_before(e, i, best_e, best_i)) {
                best_e = e;
                best_i = i;
            }
        }
        seeds[offset[k] + s] = best_i;
        last_e = best_e;
        last_i = best_i;
    }
}
