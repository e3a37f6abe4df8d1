/* The point kd-tree of a photon map: traversal nodes in preorder (KdNode of
 * types.h; a leaf's `child` is its first point), points in leaf order, and
 * one PointNode per tree node with what the illumination cut reads.
 * Host twins: gpu_core/photons/layout.py. */
#ifndef GPUGI_POINT_TREE_H
#define GPUGI_POINT_TREE_H
#include "types.h"

/* Per-node payload (96 bytes), at the node's preorder index. The points of a
 * subtree are contiguous: [first, first + count) in leaf order. */
typedef struct {
    float4 lo;         /* tight bounds of the subtree's points; w = r_p */
    float4 hi;         /* w unused */
    float4 power;      /* summed photon power (rgb) */
    float4 irradiance; /* approximate irradiance E~_p (rgb) */
    float4 normal;     /* representative unit normal (0 when unknown) */
    int first;
    int count;
    int depth;         /* root = 0 */
    int pad;
} PointNode;

/* Tree arguments every point-tree kernel takes, in this order (host:
 * PointTree.kernel_args()). Points are xyz with the original index in w
 * (as_int). */
#define POINT_TREE_PARAMS                                                    \
    const __global KdNode *pt_nodes, const __global float4 *pt_points

typedef struct {
    const __global KdNode *nodes;
    const __global float4 *points;
} PointTree;

#define POINT_TREE_MAKE() ((PointTree){pt_nodes, pt_points})

/* Photon attributes in the tree's leaf order (host:
 * PointTree.photon_args()): power rgb, incident direction (unit, pointing
 * back to where the photon came from), surface normal on the side the
 * photon arrived. */
#define PHOTON_PARAMS                                                        \
    const __global float4 *ph_power, const __global float4 *ph_dir,         \
        const __global float4 *ph_normal

typedef struct {
    const __global float4 *power;
    const __global float4 *dir;
    const __global float4 *normal;
} PhotonData;

#define PHOTON_DATA_MAKE() ((PhotonData){ph_power, ph_dir, ph_normal})

/* Tree depth bound; the kNN stack holds one entry per level. */
#define POINT_TREE_MAX_DEPTH 60

#endif
