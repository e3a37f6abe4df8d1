/* k-means clustering of shading points under the error eps [WZPB09]: the
 * nearest centre by a ring search of the uniform grid over the centres
 * (exact: it stops once no unvisited cell can hold a smaller eps), centre
 * updates, and one sample point per cluster (gpu_core/cache_clusters.py). */
#include "cache_common.h"

/* Initial centres: the seed points themselves. */
__kernel void Cache_seed_centres(const __global int *seeds, const int k, const __global float4 *pos,
                                 const __global float4 *nrm, __global float4 *cpos,
                                 __global float4 *cnrm) {
    int c = get_global_id(0);
    if (c >= k) return;
    cpos[c] = pos[seeds[c]];
    cnrm[c] = nrm[seeds[c]];
}

#define CACHE_TIE_SLOTS 8 /* near-tied centres remembered by Cache_assign */

/* Each point joins the centre of smallest eps (ties within the window:
 * lower index); counts the points whose cluster changed. cluster[] holds
 * the previous choice (-1 for none), whose eps starts the search with a
 * tight bound. Rings are visited until no unvisited centre can fall inside
 * the tie window of the smallest eps; the centres inside the window of the
 * smallest eps so far are kept in a short list. Only when more than
 * CACHE_TIE_SLOTS centres tie (coinciding centres) are the rings visited
 * again to find the lowest index. */
__kernel void Cache_assign(const __global float4 *pos, const __global float4 *nrm, const int n,
                           const __global float4 *cpos, const __global float4 *cnrm,
                           CACHE_GRID_PARAMS, const float alpha, __global int *cluster,
                           volatile __global int *changed) {
    int i = get_global_id(0);
    if (i >= n) return;
    float3 x = pos[i].xyz, nx = nrm[i].xyz;
    int prev = cluster[i];
    float best_e = FLT_MAX;
    int tie_id[CACHE_TIE_SLOTS];
    float tie_e[CACHE_TIE_SLOTS];
    int ties = 0;
    bool spilled = false;
    if (prev >= 0) {
        best_e = Cache_eps(alpha, x, nx, cpos[prev].xyz, cnrm[prev].xyz);
        tie_id[0] = prev;
        tie_e[0] = best_e;
        ties = 1;
    }
    int3 c = Cache_grid_cell(x, grid_origin, grid_dims);
    int rings = Cache_ring_count(c, grid_dims);
    int used = rings;
    for (int r = 0; r < rings; ++r) {
        CacheRing ring;
        CacheRing_begin(&ring, c, r, grid_dims);
        int cell;
        while ((cell = CacheRing_next(&ring, grid_dims)) >= 0) {
            for (int j = grid_start[cell]; j < grid_end[cell]; ++j) {
                int id = grid_items[j];
                if (id == prev) continue;
                float e = Cache_eps(alpha, x, nx, cpos[id].xyz, cnrm[id].xyz);
                if (e > Cache_tie_window(best_e)) continue;
                if (e < best_e) { /* a new smallest: drop what left its window */
                    best_e = e;
                    int kept = 0;
                    for (int t = 0; t < ties; ++t) {
                        if (tie_e[t] <= Cache_tie_window(best_e)) {
                            tie_id[kept] = tie_id[t];
                            tie_e[kept] = tie_e[t];
                            kept++;
                        }
                    }
                    ties = kept;
                }
                if (ties < CACHE_TIE_SLOTS) {
                    tie_id[ties] = id;
                    tie_e[ties] = e;
                    ties++;
                } else {
                    spilled = true;
                }
            }
        }
        /* every centre left is at least `bound` away, so its eps >= alpha * bound */
        float bound = Cache_ring_bound(x, c, r, grid_origin, grid_dims);
        if (bound == FLT_MAX || alpha * bound * (1.0f - 1e-5f) > Cache_tie_window(best_e)) {
            used = r + 1;
            break;
        }
    }
    float window = Cache_tie_window(best_e);
    int best = INT_MAX;
    for (int t = 0; t < ties; ++t) {
        if (tie_e[t] <= window) best = min(best, tie_id[t]);
    }
    for (int r = 0; spilled && r < used; ++r) {
        CacheRing ring;
        CacheRing_begin(&ring, c, r, grid_dims);
        int cell;
        while ((cell = CacheRing_next(&ring, grid_dims)) >= 0) {
            for (int j = grid_start[cell]; j < grid_end[cell]; ++j) {
                int id = grid_items[j];
                if (id < best && Cache_eps(alpha, x, nx, cpos[id].xyz, cnrm[id].xyz) <= window) best = id;
            }
        }
    }
    if (best != prev) {
        cluster[i] = best;
        atomic_inc(changed);
    }
}

/* New centre of each non-empty cluster: mean position and normalised mean
 * normal of its members (the normal stays when the members' cancel out). */
__kernel void Cache_update_centres(const __global int *start, const __global int *end,
                                   const __global int *order, const __global float4 *pos,
                                   const __global float4 *nrm, const int k,
                                   __global float4 *cpos, __global float4 *cnrm) {
    int c = get_global_id(0);
    if (c >= k || end[c] <= start[c]) return;
    float3 ps = (float3)(0.0f), ns = (float3)(0.0f);
    for (int j = start[c]; j < end[c]; ++j) {
        int i = order[j];
        ps += pos[i].xyz;
        ns += nrm[i].xyz;
    }
    cpos[c] = (float4)(ps / (float)(end[c] - start[c]), 0.0f);
    float len = sqrt(dot(ns, ns));
    if (len > 1e-12f) cnrm[c] = (float4)(ns / len, 0.0f);
}

/* Sample point of each cluster: its member of smallest eps to the centre
 * (ties within the window: lower index); -1 for an empty cluster. */
__kernel void Cache_pick_samples(const __global int *start, const __global int *end,
                                 const __global int *order, const __global float4 *pos,
                                 const __global float4 *nrm, const int k,
                                 const __global float4 *cpos, const __global float4 *cnrm,
                                 const float alpha, __global int *sample) {
    int c = get_global_id(0);
    if (c >= k) return;
    float3 cx = cpos[c].xyz, cn = cnrm[c].xyz;
    float best_e = FLT_MAX;
    for (int j = start[c]; j < end[c]; ++j) {
        int i = order[j];
        best_e = fmin(best_e, Cache_eps(alpha, pos[i].xyz, nrm[i].xyz, cx, cn));
    }
    float window = Cache_tie_window(best_e);
    int best = -1;
    for (int j = start[c]; j < end[c] && best < 0; ++j) { /* members are in index order */
        int i = order[j];
        if (Cache_eps(alpha, pos[i].xyz, nrm[i].xyz, cx, cn) <= window) best = i;
    }
    sample[c] = best;
}

/* Member of largest eps to the centre of each cluster with at least two
 * members (ties: lower index), the candidates to restart empty clusters
 * from; -1 and 0 elsewhere. */
__kernel void Cache_worst_members(const __global int *start, const __global int *end,
                                  const __global int *order, const __global float4 *pos,
                                  const __global float4 *nrm, const int k,
                                  const __global float4 *cpos, const __global float4 *cnrm,
                                  const float alpha, __global int *worst, __global float *worst_e) {
    int c = get_global_id(0);
    if (c >= k) return;
    int pick = -1;
    float pick_e = 0.0f;
    if (end[c] - start[c] >= 2) {
        float3 cx = cpos[c].xyz, cn = cnrm[c].xyz;
        for (int j = start[c]; j < end[c]; ++j) {
            int i = order[j];
            float e = Cache_eps(alpha, pos[i].xyz, nrm[i].xyz, cx, cn);
            if (pick < 0 || e > pick_e || (e == pick_e && i < pick)) {
                pick_e = e;
                pick = i;
            }
        }
    }
    worst[c] = pick;
    worst_e[c] = pick_e;
}

/* Centre `clusters[t]` restarts at point `points[t]`. */
__kernel void Cache_move_centres(const __global int *clusters, const __global int *points, const int t_count,
                                 const __global float4 *pos, const __global float4 *nrm,
                                 __global float4 *cpos, __global float4 *cnrm) {
    int t = get_global_id(0);
    if (t >= t_count) return;
    cpos[clusters[t]] = pos[points[t]];
    cnrm[clusters[t]] = nrm[points[t]];
}
