/* The triangle kd-tree as every tracing kernel sees it: its arguments, a
 * view of them, and a closest hit. Nodes are KdNode (device/structs.h) in
 * preorder: the left child of an inner node is the next node, `child` the
 * right one; a leaf's triangles are leaf_tris[child .. child + count). Where
 * blocks is not null, the same triangles are also laid out four to a block
 * from block as_int(split) on (accel/kdtree_blocks.cl), and traversal reads
 * those instead. */
#ifndef GPUGI_KDTREE_H
#define GPUGI_KDTREE_H
#include "device/structs.h"

/* Kernel parameters of the triangle kd-tree, in this order (host:
 * KdTree.kernel_args()). verts holds 3 float4 per triangle (v0, v1, v2; w
 * unused); blocks the leaf blocks, or null; bounds are the root box. */
#define KDTREE_PARAMS                                                        \
    const __global KdNode *kd_nodes, const __global int *kd_leaf_tris,       \
        const __global float4 *kd_verts, const __global float4 *kd_blocks,   \
        const float4 kd_bmin, const float4 kd_bmax

typedef struct {
    const __global KdNode *nodes;
    const __global int *leaf_tris;
    const __global float4 *verts;
    const __global float4 *blocks;
    float3 bmin;
    float3 bmax;
} KdTree;

#define KDTREE_MAKE()                                                        \
    ((KdTree){kd_nodes, kd_leaf_tris, kd_verts, kd_blocks, kd_bmin.xyz, kd_bmax.xyz})

/* A closest hit: distance, triangle index (-1 on a miss), barycentrics. */
typedef struct {
    float t;
    int tri;
    float u;
    float v;
} Hit;

#endif
