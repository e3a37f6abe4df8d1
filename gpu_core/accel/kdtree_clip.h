/* The part of a triangle inside a box, and the two parts of it on either
 * side of a plane (Sutherland-Hodgman clipping), for triangles that
 * straddle a kd-tree split plane. */
#ifndef GPUGI_KDTREE_CLIP_H
#define GPUGI_KDTREE_CLIP_H
#include "device/axis.h"

/* A triangle clipped by the 6 planes of a box has at most 9 corners; its
 * polygons have room for one more, and a side of it (a seventh plane) for
 * two more. */
#define KD_CLIP_MAX 9


/* Keep the part of polygon `in` (n corners) with sign * (x[axis] - plane)
 * >= 0; corners made on the plane lie exactly on it. Returns the count. */
inline int KdClip_plane(const float4 *in, int n, float4 *out, int axis,
                        float plane, float sign) {
    int m = 0;
    for (int i = 0; i < n; ++i) {
        float4 a = in[i];
        float4 b = in[i + 1 == n ? 0 : i + 1];
        float da = sign * (Axis_of(a, axis) - plane);
        float db = sign * (Axis_of(b, axis) - plane);
        if (da >= 0.0f) out[m++] = a;
        if ((da >= 0.0f) != (db >= 0.0f)) {
            float t = da / (da - db);
            out[m++] = Axis_with(a + t * (b - a), axis, plane);
        }
    }
    return m;
}

/* The polygon of triangle (v0, v1, v2) inside box [lo, hi] into out;
 * returns its corner count, 0 when nothing of it is inside. Planes no
 * corner crosses are skipped. */
inline int KdClip_triangle(float4 v0, float4 v1, float4 v2, float4 lo, float4 hi, float4 *out) {
    float4 poly_a[KD_CLIP_MAX + 1], poly_b[KD_CLIP_MAX + 1];
    float4 *cur = poly_a, *next = poly_b;
    cur[0] = v0;
    cur[1] = v1;
    cur[2] = v2;
    int n = 3;
    for (int axis = 0; axis < 3 && n > 0; ++axis) {
        float bound_lo = Axis_of(lo, axis), bound_hi = Axis_of(hi, axis);
        float vmin = INFINITY, vmax = -INFINITY;
        for (int i = 0; i < n; ++i) {
            vmin = fmin(vmin, Axis_of(cur[i], axis));
            vmax = fmax(vmax, Axis_of(cur[i], axis));
        }
        if (vmin < bound_lo) {
            n = KdClip_plane(cur, n, next, axis, bound_lo, 1.0f);
            float4 *swap = cur; cur = next; next = swap;
        }
        if (n > 0 && vmax > bound_hi) {
            n = KdClip_plane(cur, n, next, axis, bound_hi, -1.0f);
            float4 *swap = cur; cur = next; next = swap;
        }
    }
    for (int i = 0; i < n; ++i) out[i] = cur[i];
    return n;
}

/* Bounds of the part of polygon `in` (n corners) with sign * (x[axis] -
 * plane) >= 0; false when it has none. */
inline bool KdClip_side_bounds(const float4 *in, int n, int axis, float plane, float sign, float4 *out_lo,
                               float4 *out_hi) {
    float4 side[KD_CLIP_MAX + 2];
    int m = KdClip_plane(in, n, side, axis, plane, sign);
    if (m == 0) return false;
    float4 bmin = side[0], bmax = side[0];
    for (int i = 1; i < m; ++i) {
        bmin = fmin(bmin, side[i]);
        bmax = fmax(bmax, side[i]);
    }
    *out_lo = bmin;
    *out_hi = bmax;
    return true;
}

#endif
