/* Batch queries on the triangle kd-tree, for tests and benchmarks. */
#include "device/launch.h"
#include "accel/kdtree_traverse.h"

/* Closest hit per ray in (tmin, tmax): t, triangle index (-1 on a miss)
 * and the barycentric weights of the second and third corners. */
__kernel void KdQuery_closest(KDTREE_PARAMS, const __global float4 *org,
                              const __global float4 *dir,
                              const __global float2 *range,
                              __global float *t_out, __global int *tri_out,
                              __global float2 *uv_out, const int n) {
    int i = Launch_global_id();
    if (i >= n) return;
    KdTree tree = KDTREE_MAKE();
    Hit hit;
    KdTree_intersect(&tree, org[i].xyz, dir[i].xyz, range[i].x, range[i].y, &hit);
    t_out[i] = hit.t;
    tri_out[i] = hit.tri;
    uv_out[i] = (float2)(hit.u, hit.v);
}

/* Any hit per ray in (tmin, tmax). */
__kernel void KdQuery_occluded(KDTREE_PARAMS, const __global float4 *org,
                               const __global float4 *dir,
                               const __global float2 *range, __global int *out,
                               const int n) {
    int i = Launch_global_id();
    if (i >= n) return;
    KdTree tree = KDTREE_MAKE();
    out[i] = KdTree_occluded(&tree, org[i].xyz, dir[i].xyz, range[i].x, range[i].y) ? 1 : 0;
}
