/* Device-side types shared by every program. Each struct here has a numpy
 * dtype twin in gpu_core/layout.py; tests/test_layout.py checks sizes and
 * offsets on the device. float3 is 16 bytes, so host twins use float4. */
#ifndef GPUGI_TYPES_H
#define GPUGI_TYPES_H

/* One kd-tree node, 16 bytes, in preorder: the left child of an inner node
 * is the next node; `child` is the right child's index.
 * Inner: axis 0..2, split = plane position, count = 0.
 * Leaf:  axis 3, child = first slot in the leaf index list, count = size. */
typedef struct {
    float split;
    int axis;
    int child;
    int count;
} KdNode;

#define KD_LEAF 3

/* A closest hit: distance, triangle index (-1 on a miss), barycentrics. */
typedef struct {
    float t;
    int tri;
    float u;
    float v;
} Hit;

/* Kernel parameters every tracing kernel takes for the triangle kd-tree, in
 * this order (host: KdTree.kernel_args()). verts holds 3 float4 per
 * triangle (v0, v1, v2; w unused); bounds are the root box. */
#define KDTREE_PARAMS                                                        \
    const __global KdNode *kd_nodes, const __global int *kd_leaf_tris,       \
        const __global float4 *kd_verts, const float4 kd_bmin,               \
        const float4 kd_bmax

typedef struct {
    const __global KdNode *nodes;
    const __global int *leaf_tris;
    const __global float4 *verts;
    float3 bmin;
    float3 bmax;
} KdTree;

#define KDTREE_MAKE()                                                        \
    ((KdTree){kd_nodes, kd_leaf_tris, kd_verts, kd_bmin.xyz, kd_bmax.xyz})

#endif
