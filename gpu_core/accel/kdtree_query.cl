/* Batch queries on the triangle kd-tree, for tests and benchmarks. Rays
 * come as packed xyz triples (numpy's (N, 3) float32 rows, uploaded as
 * they are); a null t_min gives every ray the default start
 * (KdQuery_default_t_min), a null t_max the far end. */
#include "device/launch.h"
#include "accel/kdtree_traverse.h"

/* A start far enough along the ray that it does not hit the surface it
 * leaves: self_hit x the larger of the origin's largest coordinate and
 * the tree's, in units of the direction's length (0 for a zero direction). */
inline float KdQuery_default_t_min(float3 org, float3 dir, float self_hit, float magnitude) {
    float3 a = fabs(org);
    float scale = fmax(fmax(fmax(a.x, a.y), a.z), magnitude);
    float len = length(dir);
    return len > 0.0f ? self_hit * scale / len : 0.0f;
}

/* Ray i's interval (t_min, t_max), from the arrays where given. */
inline float2 KdQuery_range(int i, float3 org, float3 dir, const __global float *t_min,
                            const __global float *t_max, float self_hit, float magnitude, float far) {
    float lo = t_min ? t_min[i] : KdQuery_default_t_min(org, dir, self_hit, magnitude);
    return (float2)(lo, t_max ? t_max[i] : far);
}

/* Closest hit per ray in (t_min, t_max): t, triangle index (-1 on a miss)
 * and the barycentric weights of the second and third corners. */
__kernel void KdQuery_closest(KDTREE_PARAMS, const __global float *org, const __global float *dir,
                              const __global float *t_min, const __global float *t_max, const float self_hit,
                              const float magnitude, const float far, __global float *t_out, __global int *tri_out,
                              __global float2 *uv_out, const int n) {
    int i = Launch_global_id();
    if (i >= n) return;
    KdTree tree = KDTREE_MAKE();
    float3 o = vload3(i, org), d = vload3(i, dir);
    float2 range = KdQuery_range(i, o, d, t_min, t_max, self_hit, magnitude, far);
    Hit hit;
    KdTree_intersect(&tree, o, d, range.x, range.y, &hit);
    t_out[i] = hit.t;
    tri_out[i] = hit.tri;
    uv_out[i] = (float2)(hit.u, hit.v);
}

/* Any hit per ray in (t_min, t_max). */
__kernel void KdQuery_occluded(KDTREE_PARAMS, const __global float *org, const __global float *dir,
                               const __global float *t_min, const __global float *t_max, const float self_hit,
                               const float magnitude, const float far, __global int *out, const int n) {
    int i = Launch_global_id();
    if (i >= n) return;
    KdTree tree = KDTREE_MAKE();
    float3 o = vload3(i, org), d = vload3(i, dir);
    float2 range = KdQuery_range(i, o, d, t_min, t_max, self_hit, magnitude, far);
    out[i] = KdTree_occluded(&tree, o, d, range.x, range.y) ? 1 : 0;
}
