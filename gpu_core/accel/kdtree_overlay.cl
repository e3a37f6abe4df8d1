/* An overlay tree: a kd-tree built at some point (the base) joined with a
 * small kd-tree over the triangles that moved since (the overlay), so that
 * moving an object rebuilds only the overlay. The joined tree's root is a
 * union node whose plane is NaN: traversal takes every ray "inside the
 * plane" (accel/kdtree_traverse.h) and visits both subtrees over the whole
 * ray, without an early stop between them. */
#include "device/launch.h"
#include "device/structs.h"

/* The joined node array: the union root, then the base tree's nodes, then
 * the overlay's, their right children and leaf offsets moved to their new
 * places. */
__kernel void KdOverlay_nodes(const __global KdNode *base, const int base_count,
                              const __global KdNode *over, const int over_count,
                              const int base_refs, __global KdNode *out) {
    int i = Launch_global_id();
    if (i > base_count + over_count) return;
    if (i == 0) {
        KdNode root;
        root.split = NAN;
        root.axis = 0;
        root.child = 1 + base_count;
        root.count = 0;
        out[0] = root;
        return;
    }
    bool in_base = i <= base_count;
    KdNode n = in_base ? base[i - 1] : over[i - 1 - base_count];
    if (n.axis == KD_LEAF)
        n.child += in_base ? 0 : base_refs;
    else
        n.child += in_base ? 1 : 1 + base_count;
    out[i] = n;
}

/* The joined leaf lists: the base tree's, where a moved triangle reads -1
 * (traversal skips it: it lies elsewhere now), then the overlay's, its
 * subset indices mapped back to the scene's triangle indices (rows). */
__kernel void KdOverlay_leaves(const __global int *base_tris, const int base_refs,
                               const __global uchar *moved, const __global int *over_tris,
                               const __global int *rows, const int over_refs,
                               __global int *out) {
    int i = Launch_global_id();
    if (i < base_refs) {
        int tri = base_tris[i];
        out[i] = moved[tri] ? -1 : tri;
    } else if (i < base_refs + over_refs) {
        out[i] = rows[over_tris[i - base_refs]];
    }
}
