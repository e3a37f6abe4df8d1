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

#define PHOTON_DATA_OF(p) ((PhotonData){p##_power, p##_dir, p##_normal})
#define PHOTON_DATA_MAKE() PHOTON_DATA_OF(ph)

#endif
