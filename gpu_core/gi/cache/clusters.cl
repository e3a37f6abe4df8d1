/* k-means clustering of shading points under the error eps [WZPB09]: the
 * nearest centre by a branch-and-bound walk of the kd-tree over the centres
 * (exact: it skips only subtrees whose box cannot hold a smaller eps),
 * centre updates, and one sample point per cluster
 * (gpu_core/gi/cache/clusters.py). The tree is built once over the seeds; as
 * the centres move, each node's box is refit to the centres it holds, which
 * is all the search needs to stay exact. */
#include "device/launch.h"
#include "gi/cache/cache.h"
#include "accel/point_tree.h"

/* Initial centres: the seed points themselves. */
__kernel void Cache_seed_centres(const __global int *seeds, const int k, const __global float4 *pos,
                                 const __global float4 *nrm, __global float4 *cpos,
                                 __global float4 *cnrm) {
    int c = Launch_global_id();
    if (c >= k) return;
    cpos[c] = pos[seeds[c]];
    cnrm[c] = nrm[seeds[c]];
}

/* Box of every tree node over the current positions of its centres: lo
 * at box[2t], hi at box[2t + 1]; +-INFINITY for an empty node. */
__kernel void Cache_tree_boxes(POINT_TREE_PARAMS, const __global PointNode *pt_info, const int node_count,
                               const __global float4 *cpos, __global float4 *box) {
    int t = Launch_global_id();
    if (t >= node_count) return;
    float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
    int end = pt_info[t].first + pt_info[t].count;
    for (int j = pt_info[t].first; j < end; ++j) {
        float3 c = cpos[as_int(pt_points[j].w)].xyz;
        lo = fmin(lo, c);
        hi = fmax(hi, c);
    }
    box[2 * t] = (float4)(lo, 0.0f);
    box[2 * t + 1] = (float4)(hi, 0.0f);
}

#define CACHE_TIE_SLOTS 8 /* near-tied centres remembered by Cache_assign */
#define CACHE_WORK_STRIDE 16 /* every this many points counts its centres evaluated */

/* Whether every centre at least `dist` from the point has eps beyond
 * `window`: alpha * dist bounds eps from below (the normal term is >= 0);
 * the slack covers float rounding of the two distances. */
inline bool Cache_out_of_reach(float alpha, float dist, float window) {
    return alpha * dist * (1.0f - 1e-5f) > window;
}

/* Distance from x to the box of tree node t (0 inside). */
inline float Cache_box_distance(float3 x, const __global float4 *box, int t) {
    float3 d = fmax(fmax(box[2 * t].xyz - x, x - box[2 * t + 1].xyz), (float3)(0.0f));
    return sqrt(dot(d, d));
}

/* Depth-first walk over the leaves of the kd-tree over the centres, nearer
 * box first, skipping every subtree out of reach of the tie window. The
 * stack holds the farther children still to visit with the distance to
 * their boxes, at most one per tree level. */
typedef struct {
    int node[POINT_TREE_MAX_DEPTH + 4];
    float dist[POINT_TREE_MAX_DEPTH + 4];
    int top;
} CacheWalk;

inline void CacheWalk_begin(CacheWalk *w, float3 x, const __global float4 *box) {
    w->node[0] = 0;
    w->dist[0] = Cache_box_distance(x, box, 0);
    w->top = 1;
}

/* The next leaf (KdNode index) within reach of `window`, -1 when none is
 * left; the window may only shrink from call to call. */
inline int CacheWalk_next(CacheWalk *w, const __global KdNode *nodes, const __global float4 *box, float3 x,
                          float alpha, float window) {
    while (w->top > 0) {
        w->top--;
        if (Cache_out_of_reach(alpha, w->dist[w->top], window)) continue;
        int node = w->node[w->top];
        /* descend to the nearer child, remember the farther one */
        while (node >= 0 && nodes[node].axis != KD_LEAF) {
            int a = node + 1, b = nodes[node].child;
            float da = Cache_box_distance(x, box, a), db = Cache_box_distance(x, box, b);
            bool b_nearer = db < da;
            float far_dist = b_nearer ? da : db;
            if (!Cache_out_of_reach(alpha, far_dist, window)) {
                w->node[w->top] = b_nearer ? a : b;
                w->dist[w->top] = far_dist;
                w->top++;
            }
            node = Cache_out_of_reach(alpha, fmin(da, db), window) ? -1 : (b_nearer ? b : a);
        }
        if (node >= 0) return node;
    }
    return -1;
}

/* The centres within the tie window of the smallest eps so far: at most
 * CACHE_TIE_SLOTS of them, `spilled` once one more found no slot. */
typedef struct {
    float best_e;
    int id[CACHE_TIE_SLOTS];
    float e[CACHE_TIE_SLOTS];
    int count;
    bool spilled;
} CacheTies;

inline void CacheTies_begin(CacheTies *t) {
    t->best_e = FLT_MAX;
    t->count = 0;
    t->spilled = false;
}

/* Offer centre `id` of error e; a new smallest drops what left its window. */
inline void CacheTies_add(CacheTies *t, int id, float e) {
    if (e > Cache_tie_window(t->best_e)) return;
    if (e < t->best_e) {
        t->best_e = e;
        int kept = 0;
        for (int s = 0; s < t->count; ++s) {
            if (t->e[s] <= Cache_tie_window(e)) {
                t->id[kept] = t->id[s];
                t->e[kept] = t->e[s];
                kept++;
            }
        }
        t->count = kept;
    }
    if (t->count < CACHE_TIE_SLOTS) {
        t->id[t->count] = id;
        t->e[t->count] = e;
        t->count++;
    } else {
        t->spilled = true;
    }
}

/* Lowest index kept within the window of the smallest eps, INT_MAX for none. */
inline int CacheTies_lowest(const CacheTies *t) {
    float window = Cache_tie_window(t->best_e);
    int best = INT_MAX;
    for (int s = 0; s < t->count; ++s) {
        if (t->e[s] <= window) best = min(best, t->id[s]);
    }
    return best;
}

/* Each point joins the centre of smallest eps (ties within the window:
 * lower index); counts the points whose cluster changed (counts[0]) and,
 * over every CACHE_WORK_STRIDE-th point, the centres evaluated (counts[1]:
 * what the search costs with this tree). cluster[] holds
 * the previous choice (-1 for none), whose eps starts the search with a
 * tight bound. The kd-tree over the centres (its points' w: centre index;
 * box: Cache_tree_boxes) is walked until no
 * unvisited centre can fall inside the tie window of the smallest eps; the
 * centres inside the window of the smallest eps so far are kept in a short
 * list. Only when more than CACHE_TIE_SLOTS centres tie (coinciding
 * centres) is the tree walked again to find the lowest index. */
__kernel void Cache_assign(const __global float4 *pos, const __global float4 *nrm, const int n,
                           const __global float4 *cpos, const __global float4 *cnrm, POINT_TREE_PARAMS,
                           const __global float4 *box, const float alpha, __global int *cluster,
                           volatile __global int *counts) {
    int i = Launch_global_id();
    if (i >= n) return;
    float3 x = pos[i].xyz, nx = nrm[i].xyz;
    int prev = cluster[i];
    CacheTies ties;
    CacheTies_begin(&ties);
    if (prev >= 0) CacheTies_add(&ties, prev, Cache_eps(alpha, x, nx, cpos[prev].xyz, cnrm[prev].xyz));
    /* every centre that may fall inside the window of the smallest eps */
    CacheWalk walk;
    CacheWalk_begin(&walk, x, box);
    int leaf, evaluated = 0;
    while ((leaf = CacheWalk_next(&walk, pt_nodes, box, x, alpha, Cache_tie_window(ties.best_e))) >= 0) {
        KdNode nd = pt_nodes[leaf];
        evaluated += nd.count;
        for (int j = nd.child; j < nd.child + nd.count; ++j) {
            int id = as_int(pt_points[j].w);
            if (id != prev) CacheTies_add(&ties, id, Cache_eps(alpha, x, nx, cpos[id].xyz, cnrm[id].xyz));
        }
    }
    int best = CacheTies_lowest(&ties);
    if (ties.spilled) { /* more ties than slots: walk again for the lowest index inside the window */
        float window = Cache_tie_window(ties.best_e);
        CacheWalk_begin(&walk, x, box);
        while ((leaf = CacheWalk_next(&walk, pt_nodes, box, x, alpha, window)) >= 0) {
            KdNode nd = pt_nodes[leaf];
            for (int j = nd.child; j < nd.child + nd.count; ++j) {
                int id = as_int(pt_points[j].w);
                if (id < best && Cache_eps(alpha, x, nx, cpos[id].xyz, cnrm[id].xyz) <= window) best = id;
            }
        }
    }
    if (best != prev) {
        cluster[i] = best;
        atomic_inc(&counts[0]);
    }
    if (i % CACHE_WORK_STRIDE == 0) atomic_add(&counts[1], evaluated);
}

/* New centre of each non-empty cluster: mean position and normalised mean
 * normal of its members (the normal stays when the members' cancel out). */
__kernel void Cache_update_centres(const __global int *start, const __global int *end,
                                   const __global int *order, const __global float4 *pos,
                                   const __global float4 *nrm, const int k,
                                   __global float4 *cpos, __global float4 *cnrm) {
    int c = Launch_global_id();
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
    int c = Launch_global_id();
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
    int c = Launch_global_id();
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
    int t = Launch_global_id();
    if (t >= t_count) return;
    cpos[clusters[t]] = pos[points[t]];
    cnrm[clusters[t]] = nrm[points[t]];
}
