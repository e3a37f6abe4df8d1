/* Cache samples checked against their NEIGHBOURS nearest samples
 * (gpu_core/gi/cache/neighbours.py): lone outliers of irradiance brought
 * down to OUTLIER_RATIO times their neighbours' median luminance (where
 * that median is 0, their light shared with the samples around them that
 * face their way), and the harmonic-mean distances R_j clamped by their
 * neighbours' [Krivanek et al. 2006, neighbour clamping]. Built with KNN_K
 * = NEIGHBOURS + 1 (the sample itself comes first). */
#include "device/launch.h"
#include "accel/point_tree_knn.h"
#include "device/sampling.h"

/* Median of the first n values of v (sorted in place); 0 when n is 0. */
inline float Neighbours_median(float *v, int n) {
    for (int i = 1; i < n; ++i) {
        float x = v[i];
        int j = i - 1;
        for (; j >= 0 && v[j] > x; --j) v[j + 1] = v[j];
        v[j + 1] = x;
    }
    if (n == 0) return 0.0f;
    return n % 2 ? v[n / 2] : 0.5f * (v[n / 2 - 1] + v[n / 2]);
}

/* Whether neighbouring samples of normals a and b face the same way
 * enough to share an outlier's light. */
inline bool Neighbours_facing(float4 a, float4 b) { return dot(a.xyz, b.xyz) > NEIGHBOURS_SHARE_COS; }

/* Per sample j (tree over the sample positions): its nearest samples in
 * order, itself first, listed in ids and dists (NEIGHBOURS per sample, -1
 * and INFINITY past the last); out[j] = irradiance[j] scaled down to the
 * limit where its luminance exceeds it, counted in counts[0] (a limit of
 * 0: all its light goes to excess[j], to be shared; elsewhere excess[j] is
 * 0); and receivers[k] (zeroed before) counts the samples that list k
 * among their neighbours and face its way: those that take a share of
 * k's excess. */
__kernel void Neighbours_clamp_outliers(POINT_TREE_PARAMS, const __global float4 *positions,
                                        const __global float4 *normals, const __global float4 *irradiance,
                                        const int m, __global float4 *out, __global float4 *excess,
                                        __global int *ids, __global float *dists, volatile __global int *receivers,
                                        volatile __global int *counts) {
    int j = Launch_global_id();
    if (j >= m) return;
    PointTree tree = POINT_TREE_MAKE();
    Knn h;
    PointTree_knn(&tree, positions[j].xyz, KNN_K, INFINITY, &h);
    /* the candidates by distance (then index), the sample itself first */
    int n = Knn_count(&h);
    Knn_sort(&h);
    float lum[KNN_K];
    int count = 0;
    for (int i = 1; i < n; ++i) {
        int id = as_int(tree.points[Knn_id(&h, i)].w);
        lum[count] = Sampling_luminance(irradiance[id].xyz);
        ids[NEIGHBOURS * j + count] = id;
        dists[NEIGHBOURS * j + count] = sqrt(Knn_d2(&h, i));
        count++;
    }
    for (int i = count; i < NEIGHBOURS; ++i) {
        ids[NEIGHBOURS * j + i] = -1;
        dists[NEIGHBOURS * j + i] = INFINITY;
    }
    float limit = OUTLIER_RATIO * Neighbours_median(lum, count);
    float4 e = irradiance[j], taken = (float4)(0.0f);
    float own = Sampling_luminance(e.xyz);
    if (count > 0 && own > fmax(limit, 0.0f)) {
        if (limit > 0.0f) {
            e.xyz *= limit / own;
        } else { /* no neighbour saw any light: the sample's is shared, not dropped */
            taken.xyz = e.xyz;
            e.xyz = (float3)(0.0f);
        }
        atomic_inc(&counts[0]);
    }
    for (int i = 0; i < count; ++i) {
        int k = ids[NEIGHBOURS * j + i];
        if (Neighbours_facing(normals[j], normals[k])) atomic_inc(&receivers[k]);
    }
    out[j] = e;
    excess[j] = taken;
}

/* Each sample's irradiance (clamped) plus its share of the light taken off
 * itself and off each listed neighbour facing its way, a share being the
 * light taken off k over 1 + receivers[k]: the light stays in the
 * neighbourhood, a lone lit sample among dark ones becomes a dimmer, wider
 * patch instead of a dark one. */
__kernel void Neighbours_share_excess(const __global int *ids, const __global float4 *normals,
                                      const __global float4 *clamped, const __global float4 *excess,
                                      const __global int *receivers, const int m, __global float4 *out) {
    int j = Launch_global_id();
    if (j >= m) return;
    float3 e = clamped[j].xyz + excess[j].xyz / (float)(1 + receivers[j]);
    for (int i = 0; i < NEIGHBOURS; ++i) {
        int k = ids[NEIGHBOURS * j + i];
        if (k >= 0 && Neighbours_facing(normals[j], normals[k])) e += excess[k].xyz / (float)(1 + receivers[k]);
    }
    out[j] = (float4)(e, clamped[j].w);
}

/* One round of neighbour clamping: R_j no larger than R_k + |x_j - x_k|
 * for each listed neighbour k (r_in to r_out, a Jacobi step: rounds in
 * turn spread a small R outwards, one neighbour further each). A NaN R_j
 * takes its neighbours' bound. With `count` set, counts[1] counts the
 * samples whose R_j is now below their gathered one, r_first. */
__kernel void Neighbours_clamp_radii(const __global int *ids, const __global float *dists,
                                     const __global float *r_first, const __global float *r_in, const int m,
                                     const int count, __global float *r_out, volatile __global int *counts) {
    int j = Launch_global_id();
    if (j >= m) return;
    float r = r_in[j];
    for (int i = 0; i < NEIGHBOURS; ++i) {
        int k = ids[NEIGHBOURS * j + i];
        if (k >= 0) r = fmin(r, r_in[k] + dists[NEIGHBOURS * j + i]);
    }
    r_out[j] = r;
    if (count && r < r_first[j]) atomic_inc(&counts[1]);
}

/* The largest finite R_j (bits of a non-negative float order as ints):
 * bound[0], zeroed before. */
__kernel void Neighbours_finite_max(const __global float *r, const int m, volatile __global int *bound) {
    int j = Launch_global_id();
    if (j >= m || !isfinite(r[j])) return;
    atomic_max(&bound[0], as_int(fmax(r[j], 0.0f)));
}

/* A sample whose gather rays met nothing, and whose neighbours' clamping
 * did not bound it, takes the largest finite R_j (when there is one):
 * an infinite R_j would cover every point facing its way with a weight
 * that drowns every other sample's. counts[2] counts them. */
__kernel void Neighbours_bound_infinite(__global float *r, const int m, const __global int *bound,
                                        volatile __global int *counts) {
    int j = Launch_global_id();
    if (j >= m || !(isinf(r[j]) && r[j] > 0.0f) || bound[0] <= 0) return; /* NaN: left as it is */
    r[j] = as_float(bound[0]);
    atomic_inc(&counts[2]);
}
