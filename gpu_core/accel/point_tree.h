/* The point kd-tree (photon maps, cut centres, k-means centres): traversal
 * nodes in preorder (KdNode; a leaf's `child` is its first point), points in
 * leaf order, and one PointNode per tree node (device/structs.h) with what
 * the illumination cut reads. */
#ifndef GPUGI_POINT_TREE_H
#define GPUGI_POINT_TREE_H
#include "device/structs.h"

/* Tree arguments every point-tree kernel takes, in this order (host:
 * PointTree.kernel_args()). Points are xyz with the original index in w
 * (as_int). A kernel reading two trees names them: POINT_TREE_PARAMS_OF(p)
 * declares p_nodes and p_points, POINT_TREE_OF(p) views them. */
#define POINT_TREE_PARAMS_OF(p) const __global KdNode *p##_nodes, const __global float4 *p##_points
#define POINT_TREE_PARAMS POINT_TREE_PARAMS_OF(pt)

typedef struct {
    const __global KdNode *nodes;
    const __global float4 *points;
} PointTree;

#define POINT_TREE_OF(p) ((PointTree){p##_nodes, p##_points})
#define POINT_TREE_MAKE() POINT_TREE_OF(pt)

/* Photon attributes in the tree's leaf order (host:
 * PointTree.photon_args()): power rgb, incident direction (unit, pointing
 * back to where the photon came from), surface normal on the side the
 * photon arrived. */
#define PHOTON_PARAMS_OF(p)                                                  \
    const __global float4 *p##_power, const __global float4 *p##_dir,       \
        const __global float4 *p##_normal
#define PHOTON_PARAMS PHOTON_PARAMS_OF(ph)

typedef struct {
    const __global float4 *power;
    const __global float4 *dir;
    const __global float4 *normal;
} PhotonData;

/* A node's approximate irradiance E~_p = max(0, n_p . sum_i w_i Phi_i[c]) /
 * r_p^2 per channel c, from the moments m_c = sum_i w_i Phi_i[c] of its
 * photons (w_i incident directions), its representative normal n_p and
 * size r_p; 0 where it is not finite. */
inline float3 PointNode_irradiance(float3 n_p, float r_p, float3 m0, float3 m1, float3 m2) {
    if (!(r_p > 0.0f)) return (float3)(0.0f);
    float3 e = (float3)(fmax(0.0f, dot(n_p, m0)), fmax(0.0f, dot(n_p, m1)), fmax(0.0f, dot(n_p, m2))) * (1.0f / (r_p * r_p));
    return isfinite(e.x) && isfinite(e.y) && isfinite(e.z) ? e : (float3)(0.0f);
}

#define PHOTON_DATA_OF(p) ((PhotonData){p##_power, p##_dir, p##_normal})
#define PHOTON_DATA_MAKE() PHOTON_DATA_OF(ph)

#endif
