/* k nearest neighbours in the point kd-tree: a bounded max-heap of k
 * candidates, filled by a depth-first descent that visits the near child
 * first and skips any subtree whose plane distance cannot beat the current
 * k-th distance. KNN_K, a compile-time define, is the heap's capacity (the
 * program is built per capacity) and every search's k; a program whose
 * searches ask for fewer (KNN_VARIABLE_K: the photon searches, built per
 * power-of-two capacity, accel/point_tree.py knn_capacity) keeps k per
 * search. */
#ifndef GPUGI_POINT_TREE_KNN_H
#define GPUGI_POINT_TREE_KNN_H
#include "accel/point_tree.h"
#include "device/axis.h"
#include "device/inline.h"

#ifndef KNN_K
#error "KNN_K must be defined"
#endif

/* The candidate set: the first k candidates are appended, then made a
 * max-heap (farthest first) whose top every later candidate replaces.
 * Each entry is one 64-bit key, the squared distance's bits above the
 * point's index: keys order as distances do (distances are never
 * negative), and a move is one copy. `worst` bounds the search: the
 * squared search radius until the set is full, then the farthest entry. */
typedef struct {
    ulong key[KNN_K];
#ifdef KNN_VARIABLE_K
    int k; /* entries wanted, at most KNN_K */
#endif
    int n; /* entries filled */
    float worst;
} Knn;

/* The number of entries wanted */
#ifdef KNN_VARIABLE_K
#define Knn_wanted(h) ((h)->k)
#else
#define Knn_wanted(h) KNN_K
#endif

inline ulong Knn_key(float d2, int id) { return ((ulong)as_uint(d2) << 32) | (uint)id; }

/* Squared distance and point (index in the tree's leaf order) of entry i;
 * entries past Knn_count are empty. */
inline float Knn_d2(const Knn *h, int i) { return as_float((uint)(h->key[i] >> 32)); }
inline int Knn_id(const Knn *h, int i) { return (int)(uint)h->key[i]; }

/* Empty, for the k nearest, bounded just beyond max_d2 so points at
 * exactly max_d2 still enter. */
inline void Knn_init(Knn *h, int k, float max_d2) {
#ifdef KNN_VARIABLE_K
    h->k = clamp(k, 1, KNN_K);
#endif
    h->n = 0;
    h->worst = isinf(max_d2) ? INFINITY : nextafter(max_d2, INFINITY);
}

/* Put key at position i of a max-heap of n entries, moving larger
 * children up. */
inline void Knn_sift(Knn *h, int i, int n, ulong key) {
    while (true) {
        int c = 2 * i + 1;
        if (c >= n) break;
        if (c + 1 < n && h->key[c + 1] > h->key[c]) c++;
        if (h->key[c] <= key) break;
        h->key[i] = h->key[c];
        i = c;
    }
    h->key[i] = key;
}

/* Make the first n entries a max-heap. */
inline void Knn_heapify(Knn *h, int n) {
    for (int i = n / 2 - 1; i >= 0; --i) Knn_sift(h, i, n, h->key[i]);
}

/* Add a candidate closer than h->worst. */
GPUGI_HOT_INLINE void Knn_push(Knn *h, float d2, int id) {
    if (h->n < Knn_wanted(h)) {
        h->key[h->n] = Knn_key(d2, id);
        if (++h->n < Knn_wanted(h)) return;
        Knn_heapify(h, Knn_wanted(h));
    } else {
        Knn_sift(h, 0, Knn_wanted(h), Knn_key(d2, id));
    }
    h->worst = Knn_d2(h, 0);
}

/* Candidates found. */
inline int Knn_count(const Knn *h) { return h->n; }

/* Sort the candidates nearest first (then by index), in place: an
 * insertion sort farthest first, then reversed. A heap's array is in that
 * order but for about n^2 / 10 pairs (253 of a full heap of 50's 1,225):
 * 0.92x the batch's time of a heap sort at k = 50 on a CPU. */
inline void Knn_sort(Knn *h) {
    int n = h->n;
    for (int i = 1; i < n; ++i) {
        ulong key = h->key[i];
        int j = i;
        for (; j > 0 && h->key[j - 1] < key; --j) h->key[j] = h->key[j - 1];
        h->key[j] = key;
    }
    for (int i = 0, j = n - 1; i < j; ++i, --j) {
        ulong far = h->key[i];
        h->key[i] = h->key[j];
        h->key[j] = far;
    }
}

/* The k nearest points to q within sqrt(max_d2), left in h.
 * Depth-first, near child first. A far child is pushed with the squared
 * distance to its splitting plane; popped entries are skipped once that
 * bound cannot beat the farthest candidate. (The tighter distance to the
 * far cell, kept incrementally, measured no faster on photon maps.) */
inline void PointTree_knn(const PointTree *tree, float3 q, int k, float max_d2, Knn *h) {
    Knn_init(h, k, max_d2);
    int stack_node[POINT_TREE_MAX_DEPTH + 4];
    float stack_bound[POINT_TREE_MAX_DEPTH + 4];
    int top = 0;
    int node = 0;
    while (true) {
        KdNode nd = tree->nodes[node];
        if (nd.axis != KD_LEAF) {
            /* descend to the near side, remember the far side */
            float diff = Axis_of3(q, nd.axis) - nd.split;
            int near_child = diff < 0.0f ? node + 1 : nd.child;
            int far_child = diff < 0.0f ? nd.child : node + 1;
            float bound = diff * diff;
            if (bound < h->worst) {
                stack_node[top] = far_child;
                stack_bound[top] = bound;
                top++;
            }
            node = near_child;
            continue;
        }
        /* leaf: its points four at a time, their distances as one vector
         * (each the same sum of squares as one at a time), then pushed in
         * order where they beat the farthest candidate; the rest one by one */
        int end = nd.child + nd.count;
        int i = nd.child;
        for (; i + 4 <= end; i += 4) {
            float4 p0 = tree->points[i], p1 = tree->points[i + 1], p2 = tree->points[i + 2], p3 = tree->points[i + 3];
            float4 dx = (float4)(p0.x, p1.x, p2.x, p3.x) - (float4)(q.x);
            float4 dy = (float4)(p0.y, p1.y, p2.y, p3.y) - (float4)(q.y);
            float4 dz = (float4)(p0.z, p1.z, p2.z, p3.z) - (float4)(q.z);
            float4 d2 = dx * dx + dy * dy + dz * dz;
            int4 near = d2 < (float4)(h->worst);
            if (!any(near)) continue; /* the bound only shrinks */
            if (d2.x < h->worst) Knn_push(h, d2.x, i);
            if (d2.y < h->worst) Knn_push(h, d2.y, i + 1);
            if (d2.z < h->worst) Knn_push(h, d2.z, i + 2);
            if (d2.w < h->worst) Knn_push(h, d2.w, i + 3);
        }
        for (; i < end; ++i) {
            float3 d = tree->points[i].xyz - q;
            float d2 = d.x * d.x + d.y * d.y + d.z * d.z;
            if (d2 < h->worst) Knn_push(h, d2, i);
        }
        /* next far side that can still hold a closer point */
        node = -1;
        while (top > 0) {
            top--;
            if (stack_bound[top] < h->worst) {
                node = stack_node[top];
                break;
            }
        }
        if (node < 0) return;
    }
}

#endif
