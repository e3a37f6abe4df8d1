/* Batch queries on the triangle kd-tree, for tests and benchmarks. */
#include "kdtree_traverse.h"

/* Closest hit per ray: t and triangle index (-1 on a miss). */
__kernel void KdQuery_closest(KDTREE_PARAMS, const __global float4 *org,
                              const __global float4 *dir,
                              const __global float *tmax, __global float *t_out,
                              __global int *tri_out, const int n) {
    int i = get_global_id(0);
    if (i >= n) return;
    KdTree tree = KDTREE_MAKE();
    Hit hit;
    KdTree_intersect(&tree, org[i].xyz, dir[i].xyz, 0.0f, tmax[i], &hit);
    t_out[i] = hit.t;
    tri_out[i] = hit.tri;
}

/* Any hit per ray before tmax. */
__kernel void KdQuery_occluded(KDTREE_PARAMS, const __global float4 *org,
                               const __global float4 *dir,
                               const __global float *tmax, __global int *out,
                               const int n) {
    int i = get_global_id(0);
    if (i >= n) return;
    KdTree tree = KDTREE_MAKE();
    out[i] = KdTree_occluded(&tree, org[i].xyz, dir[i].xyz, 0.0f, tmax[i]) ? 1 : 0;
}
