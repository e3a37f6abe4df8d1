/* Leaf blocks of the triangle kd-tree (accel/kdtree.h): each leaf's
 * triangles in blocks of KD_BLOCK_LANES, their corners one coordinate per
 * float4 (a lane a triangle), so that traversal tests four triangles at once
 * (KdTree_block in accel/kdtree_traverse.h). A block is KD_BLOCK_ROWS float4:
 * v0.x, v0.y, v0.z, v1.x, ... v2.z, then the triangles' indices (int bits),
 * -1 in an empty lane or where the leaf lists -1 (an overlay tree's moved
 * triangle). A leaf's first block goes into its split (int bits), which a
 * leaf does not otherwise use. */
#include "device/launch.h"
#include "device/structs.h"
#include "accel/kdtree.h"

#if KD_BLOCK_LANES != 4 || KD_BLOCK_ROWS != 10
#error "a block is nine float4 of corners and one int4 of indices (KdTree_block reads it so)"
#endif

/* Blocks of node i: ceil(count / 4) for a leaf, 0 for an inner node. */
__kernel void KdBlocks_count(const __global KdNode *nodes, const int n, __global int *count) {
    int i = Launch_global_id();
    if (i >= n) return;
    KdNode nd = nodes[i];
    count[i] = nd.axis == KD_LEAF ? (nd.count + KD_BLOCK_LANES - 1) / KD_BLOCK_LANES : 0;
}

/* Leaf i's blocks from its first block (the exclusive scan of the counts)
 * on, and that first block into its split. */
__kernel void KdBlocks_fill(__global KdNode *nodes, const __global int *first, const __global int *leaf_tris,
                            const __global float4 *verts, const int n, __global float4 *blocks) {
    int i = Launch_global_id();
    if (i >= n || nodes[i].axis != KD_LEAF) return;
    KdNode nd = nodes[i];
    int b0 = first[i];
    nodes[i].split = as_float(b0);
    for (int k = 0; k < nd.count; k += KD_BLOCK_LANES) {
        __global float4 *blk = blocks + (size_t)KD_BLOCK_ROWS * (b0 + k / KD_BLOCK_LANES);
        float c[9][KD_BLOCK_LANES];
        int id[KD_BLOCK_LANES];
        for (int lane = 0; lane < KD_BLOCK_LANES; ++lane) {
            int tri = k + lane < nd.count ? leaf_tris[nd.child + k + lane] : -1;
            id[lane] = tri;
            for (int v = 0; v < 3; ++v) {
                float4 p = tri >= 0 ? verts[3 * tri + v] : (float4)(0.0f);
                c[3 * v][lane] = p.x;
                c[3 * v + 1][lane] = p.y;
                c[3 * v + 2][lane] = p.z;
            }
        }
        for (int r = 0; r < 9; ++r) blk[r] = (float4)(c[r][0], c[r][1], c[r][2], c[r][3]);
        blk[9] = as_float4((int4)(id[0], id[1], id[2], id[3]));
    }
}
