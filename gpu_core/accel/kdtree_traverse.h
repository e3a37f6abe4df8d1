/* Closest-hit and any-hit traversal of the triangle kd-tree (KdNode, accel/kdtree.h):
 * front-to-back descent with a fixed stack (the builder never makes a tree
 * deeper than KD_MAX_DEPTH) and a watertight ray/triangle test [Woop,
 * Benthin, Wald 2013], so rays through shared edges and corners do not slip
 * between triangles. */
#ifndef GPUGI_KDTREE_TRAVERSE_H
#define GPUGI_KDTREE_TRAVERSE_H
#include "accel/kdtree.h"
#include "device/axis.h"
#include "device/inline.h"

/* Relative rounding error allowed for in the ray's distances to planes. */
#define KD_T_SLACK 1.0e-6f

/* A ray set up for the watertight test: corners are moved to the ray
 * origin, their axes permuted so the ray's dominant axis is z (keeping
 * the winding), then sheared so the ray runs along +z. */
typedef struct {
    float4 org;
    uint4 perm; /* kx, ky, kz, w */
    float sx, sy, sz;
} KdRay;

inline KdRay KdTree_ray(float3 org, float3 dir) {
    float3 ad = fabs(dir);
    int kz = (ad.x >= ad.y && ad.x >= ad.z) ? 0 : (ad.y >= ad.z ? 1 : 2);
    int kx = kz == 2 ? 0 : kz + 1;
    int ky = kx == 2 ? 0 : kx + 1;
    float dz = Axis_of3(dir, kz);
    if (dz < 0.0f) {
        int swap = kx;
        kx = ky;
        ky = swap;
    }
    KdRay ray;
    ray.org = (float4)(org, 0.0f);
    ray.perm = (uint4)(kx, ky, kz, 3);
    ray.sx = Axis_of3(dir, kx) / dz;
    ray.sy = Axis_of3(dir, ky) / dz;
    ray.sz = 1.0f / dz;
    return ray;
}

/* Watertight ray/triangle test; on a hit with t in (tmin, tmax) writes t
 * and the barycentric weights u of v1 and v of v2. Edge functions of an
 * edge shared by two triangles are exact negations (no contraction into
 * fused multiply-adds), and an edge value of exactly 0 counts as inside. */
inline bool KdTree_triangle(const KdRay *ray, float4 v0, float4 v1, float4 v2,
                            float tmin, float tmax, float *t, float *u,
                            float *v) {
#pragma OPENCL FP_CONTRACT OFF
    float4 d0 = v0 - ray->org, d1 = v1 - ray->org, d2 = v2 - ray->org;
    int kx = ray->perm.x, ky = ray->perm.y, kz = ray->perm.z;
    float4 a = (float4)(Axis_of(d0, kx), Axis_of(d0, ky), Axis_of(d0, kz), 0.0f);
    float4 b = (float4)(Axis_of(d1, kx), Axis_of(d1, ky), Axis_of(d1, kz), 0.0f);
    float4 c = (float4)(Axis_of(d2, kx), Axis_of(d2, ky), Axis_of(d2, kz), 0.0f);
    float ax = a.x - ray->sx * a.z, ay = a.y - ray->sy * a.z;
    float bx = b.x - ray->sx * b.z, by = b.y - ray->sy * b.z;
    float cx = c.x - ray->sx * c.z, cy = c.y - ray->sy * c.z;
    float e0 = cx * by - cy * bx;
    float e1 = ax * cy - ay * cx;
    float e2 = bx * ay - by * ax;
    if ((e0 < 0.0f || e1 < 0.0f || e2 < 0.0f) && (e0 > 0.0f || e1 > 0.0f || e2 > 0.0f))
        return false;
    float det = e0 + e1 + e2;
    if (det == 0.0f) return false;
    float inv = 1.0f / det;
    float tt = (e0 * a.z + e1 * b.z + e2 * c.z) * ray->sz * inv;
    if (!(tt > tmin && tt < tmax)) return false;
    *t = tt;
    *u = e1 * inv;
    *v = e2 * inv;
    return true;
}

/* One lane of a vector. */
inline float KdTree_lane(float4 v, int lane) { return lane == 0 ? v.x : (lane == 1 ? v.y : (lane == 2 ? v.z : v.w)); }

/* KdTree_triangle for the four lanes of a leaf block (accel/kdtree_blocks.cl)
 * at once, lane by lane the same arithmetic, so the same outcome for each
 * triangle: the index of the nearest triangle hit with t in (tmin, tmax)
 * (the lowest lane on a tie, as the leaf list's order would have it), or
 * with any_hit the lowest lane hit (the list's first), its t and
 * barycentrics; -1 when none is. */
GPUGI_HOT_INLINE int KdTree_block(const KdRay *ray, const __global float4 *blk, float tmin, float tmax, bool any_hit,
                                  float *t, float *u, float *v) {
#pragma OPENCL FP_CONTRACT OFF
    /* corners relative to the ray origin, coordinate by coordinate */
    float4 ox = (float4)(ray->org.x), oy = (float4)(ray->org.y), oz = (float4)(ray->org.z);
    float4 d0[3] = {blk[0] - ox, blk[1] - oy, blk[2] - oz};
    float4 d1[3] = {blk[3] - ox, blk[4] - oy, blk[5] - oz};
    float4 d2[3] = {blk[6] - ox, blk[7] - oy, blk[8] - oz};
    /* permuted and sheared as KdTree_triangle does */
    int kx = ray->perm.x, ky = ray->perm.y, kz = ray->perm.z;
    float4 sx = (float4)(ray->sx), sy = (float4)(ray->sy);
    float4 az = d0[kz], bz = d1[kz], cz = d2[kz];
    float4 ax = d0[kx] - sx * az, ay = d0[ky] - sy * az;
    float4 bx = d1[kx] - sx * bz, by = d1[ky] - sy * bz;
    float4 cx = d2[kx] - sx * cz, cy = d2[ky] - sy * cz;
    float4 e0 = cx * by - cy * bx;
    float4 e1 = ax * cy - ay * cx;
    float4 e2 = bx * ay - by * ax;
    /* inside: no edge value of each sign; a lane holding no triangle never is */
    float4 zero = (float4)(0.0f);
    int4 ids = as_int4(blk[9]);
    int4 below = (e0 < zero) | (e1 < zero) | (e2 < zero);
    int4 above = (e0 > zero) | (e1 > zero) | (e2 > zero);
    float4 det = e0 + e1 + e2;
    int4 ok = ~(below & above) & (det != zero) & (ids >= (int4)(0));
    if (!any(ok)) return -1;
    float4 inv = (float4)(1.0f) / det;
    float4 tt = (e0 * az + e1 * bz + e2 * cz) * (float4)(ray->sz) * inv;
    ok &= (tt > (float4)(tmin)) & (tt < (float4)(tmax));
    if (!any(ok)) return -1;
    int lane;
    if (any_hit) {
        lane = ok.x ? 0 : (ok.y ? 1 : (ok.z ? 2 : 3));
    } else {
        /* the nearest lane, the lowest on a tie (INFINITY in the others) */
        float4 tk = select((float4)(INFINITY), tt, ok);
        lane = 0;
        float best = tk.x;
        if (tk.y < best) {
            best = tk.y;
            lane = 1;
        }
        if (tk.z < best) {
            best = tk.z;
            lane = 2;
        }
        if (tk.w < best) lane = 3;
    }
    *t = KdTree_lane(tt, lane);
    *u = KdTree_lane(e1 * inv, lane);
    *v = KdTree_lane(e2 * inv, lane);
    return as_int(KdTree_lane(as_float4(ids), lane));
}

/* Clip [tmin, tmax] to the root box; false when the ray misses it. */
inline bool KdTree_clip_root(const KdTree *tree, float3 org, float3 inv_dir,
                             float *tmin, float *tmax) {
    float3 t0 = (tree->bmin - org) * inv_dir;
    float3 t1 = (tree->bmax - org) * inv_dir;
    float3 lo = fmin(t0, t1), hi = fmax(t0, t1);
    float a = fmax(fmax(lo.x, lo.y), fmax(lo.z, *tmin));
    float b = fmin(fmin(hi.x, hi.y), fmin(hi.z, *tmax));
    if (!(a <= b)) return false;
    *tmin = a;
    *tmax = b;
    return true;
}

/* Shared descent: with any_hit set, returns at the first hit found. Each
 * leaf tests its triangles over the whole ray interval, so a triangle is
 * found in whichever of its leaves the ray reaches first. Cell intervals
 * [t0, t1] are widened by the rounding error of the plane distances, so a
 * ray through a cell's edge or corner never skips the cell it hits in;
 * the search stops once the closest hit so far lies before t_exit, where
 * the cell ends for certain. */
inline bool KdTree_traverse(const KdTree *tree, float3 org, float3 dir,
                            float tmin, float tmax, bool any_hit, Hit *hit) {
    hit->t = tmax;
    hit->tri = -1;
    hit->u = hit->v = 0.0f;
    float3 inv_dir = 1.0f / dir;
    float t0 = tmin, t1 = tmax;
    if (!KdTree_clip_root(tree, org, inv_dir, &t0, &t1)) return false;
    KdRay ray = KdTree_ray(org, dir);
    /* per axis: origin, inverse direction and the absolute error of
     * (split - org) / dir, indexed by a node's axis */
    float3 reach = fmax(fmax(fabs(org), fabs(tree->bmin)), fabs(tree->bmax));
    float3 slack3 = KD_T_SLACK * fmax(fmax(reach.x, reach.y), reach.z) * fabs(inv_dir);
    float o_axis[3] = {org.x, org.y, org.z};
    float inv_axis[3] = {inv_dir.x, inv_dir.y, inv_dir.z};
    float slack[3] = {slack3.x, slack3.y, slack3.z};
    float t_exit = t1;
    int stack_node[KD_MAX_DEPTH];
    float stack_t0[KD_MAX_DEPTH], stack_t1[KD_MAX_DEPTH], stack_exit[KD_MAX_DEPTH];
    int top = 0;
    int node = 0;
    while (true) {
        KdNode n = tree->nodes[node];
        /* descend to the first leaf along the ray, stacking the second
         * side of every plane the interval may cross */
        while (n.axis != KD_LEAF) {
            float inv = inv_axis[n.axis];
            float t_split = (n.split - o_axis[n.axis]) * inv;
            /* the side the ray is on before the plane: below unless it runs downwards */
            int first = inv < 0.0f ? n.child : node + 1;
            int second = inv < 0.0f ? node + 1 : n.child;
            /* the ray runs inside the plane, or the node is an overlay
             * tree's union root (its plane NaN): both sides */
            if (isnan(t_split)) {
                stack_node[top] = second;
                stack_t0[top] = t0;
                stack_t1[top] = t1;
                stack_exit[top] = t_exit;
                top++;
                t_exit = fmin(t_exit, t0); /* the sides overlap: no early stop */
                node = first;
                n = tree->nodes[node];
                continue;
            }
            if (isinf(t_split)) { /* parallel to the plane: one side only */
                node = t_split > 0.0f ? first : second;
                n = tree->nodes[node];
                continue;
            }
            float err = slack[n.axis] + KD_T_SLACK * fabs(t_split);
            bool visit_first = t_split + err >= t0;
            bool visit_second = t_split - err <= t1;
            if (visit_first && visit_second) {
                stack_node[top] = second;
                stack_t0[top] = fmax(t0, t_split - err);
                stack_t1[top] = t1;
                stack_exit[top] = t_exit;
                top++;
                t1 = fmin(t1, t_split + err);
                t_exit = fmin(t_exit, t_split - err);
            }
            node = visit_first ? first : second;
            n = tree->nodes[node];
        }
        /* leaf: its triangles against the whole remaining ray, four at a
         * time from its blocks where the tree has them, else one by one
         * from its list (an overlay tree's base lists a moved triangle as
         * -1: kdtree_overlay.cl) */
        if (tree->blocks) {
            const __global float4 *blk = tree->blocks + (size_t)KD_BLOCK_ROWS * as_int(n.split);
            for (int k = 0; k < n.count; k += KD_BLOCK_LANES, blk += KD_BLOCK_ROWS) {
                float t, u, v;
                int tri = KdTree_block(&ray, blk, tmin, hit->t, any_hit, &t, &u, &v);
                if (tri >= 0) {
                    hit->t = t;
                    hit->tri = tri;
                    hit->u = u;
                    hit->v = v;
                    if (any_hit) return true;
                }
            }
        } else {
            for (int i = 0; i < n.count; ++i) {
                int tri = tree->leaf_tris[n.child + i];
                if (tri < 0) continue;
                float t, u, v;
                if (KdTree_triangle(&ray, tree->verts[3 * tri], tree->verts[3 * tri + 1],
                                    tree->verts[3 * tri + 2], tmin, hit->t, &t, &u, &v)) {
                    hit->t = t;
                    hit->tri = tri;
                    hit->u = u;
                    hit->v = v;
                    if (any_hit) return true;
                }
            }
        }
        if (hit->tri >= 0 && hit->t <= t_exit) return true;
        /* next stacked cell that may still hold a closer hit */
        do {
            if (top == 0) return hit->tri >= 0;
            top--;
        } while (stack_t0[top] > hit->t);
        node = stack_node[top];
        t0 = stack_t0[top];
        t1 = stack_t1[top];
        t_exit = stack_exit[top];
    }
}

/* Closest hit along org + t dir, t in (tmin, tmax); hit->tri = -1 on a miss. */
inline bool KdTree_intersect(const KdTree *tree, float3 org, float3 dir,
                             float tmin, float tmax, Hit *hit) {
    return KdTree_traverse(tree, org, dir, tmin, tmax, false, hit);
}

/* Whether anything blocks org + t dir for t in (tmin, tmax). */
inline bool KdTree_occluded(const KdTree *tree, float3 org, float3 dir,
                            float tmin, float tmax) {
    Hit hit;
    return KdTree_traverse(tree, org, dir, tmin, tmax, true, &hit);
}

#endif
