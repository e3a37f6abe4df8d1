/* Irradiance from the illumination cut at a surface point [WZPB09]: the
 * cut nodes j around y, weighted w_j = K(|p_j - y| / L_j) max(0, n_j . n_y)
 * with K(x) = 1 - x^2 (0 past x = 1) and L_j the node's size; a point no
 * node covers takes the nearest node facing its way (looked for among the
 * CUT_FALLBACK nearest when none of those around it faces it), so
 * gathering never meets holes. Used by final gathering (gather.cl) and the
 * batch lookup (cut.cl). The nodes are found by kNN in a point tree over
 * their centres (KNN_K at least CUT_FALLBACK, KNN_VARIABLE_K). */
#ifndef GPUGI_CUT_LOOKUP_H
#define GPUGI_CUT_LOOKUP_H
#include "accel/point_tree_knn.h"

/* CUT_NEIGHBOURS (cut nodes considered around a lookup point) and
 * CUT_FALLBACK come from the host (gpu_core/gi/cut.py lookup_defines). */

/* The cut: a point tree over its node centres (cut_nodes, cut_points), and
 * per node (in the tree's original order) the centre with L_j in w, the
 * unit normal and the irradiance E_p. */
#define CUT_PARAMS                                                           \
    POINT_TREE_PARAMS_OF(cut), const __global float4 *cut_centre,           \
        const __global float4 *cut_normal, const __global float4 *cut_irradiance, const int cut_count

typedef struct {
    PointTree tree;
    const __global float4 *centre;
    const __global float4 *normal;
    const __global float4 *irradiance;
    int count;
} Cut;

#define CUT_MAKE() ((Cut){POINT_TREE_OF(cut), cut_centre, cut_normal, cut_irradiance, cut_count})

/* The node nearest y (then of lowest index) among those found in h that
 * face n_y's way, -1 for none. */
inline int CutLookup_nearest_facing(const Cut *cut, const Knn *h, float3 n_y) {
    int nearest = -1;
    ulong nearest_key = ULONG_MAX;
    for (int i = 0; i < Knn_count(h); ++i) {
        int j = as_int(cut->tree.points[Knn_id(h, i)].w);
        if (dot(cut->normal[j].xyz, n_y) > 0.0f && h->key[i] < nearest_key) {
            nearest_key = h->key[i];
            nearest = j;
        }
    }
    return nearest;
}

inline float3 CutLookup_irradiance(const Cut *cut, float3 y, float3 n_y) {
    float3 none = (float3)(0.0f);
    if (cut->count <= 0) return none;
    Knn h;
    PointTree_knn(&cut->tree, y, min(CUT_NEIGHBOURS, cut->count), INFINITY, &h);
    float3 sum = none;
    float total = 0.0f;
    for (int i = 0; i < Knn_count(&h); ++i) {
        int j = as_int(cut->tree.points[Knn_id(&h, i)].w);
        float size = fmax(cut->centre[j].w, 1e-30f);
        float x2 = Knn_d2(&h, i) / (size * size);
        float w = fmax(1.0f - x2, 0.0f) * fmax(dot(cut->normal[j].xyz, n_y), 0.0f);
        total += w;
        sum += w * cut->irradiance[j].xyz;
    }
    if (total > 0.0f) return sum / total;
    int nearest = CutLookup_nearest_facing(cut, &h, n_y);
    if (nearest < 0 && cut->count > CUT_NEIGHBOURS) {
        PointTree_knn(&cut->tree, y, min(CUT_FALLBACK, cut->count), INFINITY, &h);
        nearest = CutLookup_nearest_facing(cut, &h, n_y);
    }
    return nearest >= 0 ? cut->irradiance[nearest].xyz : none;
}

/* The irradiance as a light estimate: non-finite parts 0, never negative
 * (gather rays and the image's glossy paths). */
inline float3 CutLookup_light(const Cut *cut, float3 y, float3 n_y) {
    float3 e = CutLookup_irradiance(cut, y, n_y);
    e = (float3)(isfinite(e.x) ? e.x : 0.0f, isfinite(e.y) ? e.y : 0.0f, isfinite(e.z) ? e.z : 0.0f);
    return fmax(e, (float3)(0.0f));
}

#endif
