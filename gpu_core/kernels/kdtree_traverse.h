/* Closest-hit and any-hit traversal of the triangle kd-tree (types.h KdNode).
 * Stack-based front-to-back descent over the ray's [tmin, tmax] interval. */
#ifndef GPUGI_KDTREE_TRAVERSE_H
#define GPUGI_KDTREE_TRAVERSE_H
#include "types.h"

#define KD_STACK_SIZE 48

/* Moller-Trumbore ray/triangle test; writes t and barycentrics on a hit. */
inline bool KdTree_triangle(float3 org, float3 dir, float3 v0, float3 v1,
                            float3 v2, float tmin, float tmax, float *t,
                            float *u, float *v) {
    float3 e1 = v1 - v0, e2 = v2 - v0;
    float3 p = cross(dir, e2);
    float det = dot(e1, p);
    if (det == 0.0f) return false;
    float inv = 1.0f / det;
    float3 s = org - v0;
    float uu = dot(s, p) * inv;
    if (uu < 0.0f || uu > 1.0f) return false;
    float3 q = cross(s, e1);
    float vv = dot(dir, q) * inv;
    if (vv < 0.0f || uu + vv > 1.0f) return false;
    float tt = dot(e2, q) * inv;
    if (!(tt > tmin && tt < tmax)) return false;
    *t = tt;
    *u = uu;
    *v = vv;
    return true;
}

/* Clip [tmin, tmax] to the root box; false when the ray misses it. */
inline bool KdTree_clip_root(const KdTree *tree, float3 org, float3 inv_dir,
                             float *tmin, float *tmax) {
    float3 t0 = (tree->bmin - org) * inv_dir;
    float3 t1 = (tree->bmax - org) * inv_dir;
    float3 lo = fmin(t0, t1), hi = fmax(t0, t1);
    float a = fmax(fmax(lo.x, lo.y), fmax(lo.z, *tmin));
    float b = fmin(fmin(hi.x, hi.y), fmin(hi.z, *tmax));
    if (a > b) return false;
    *tmin = a;
    *tmax = b;
    return true;
}

/* Shared descent: with any_hit set, returns at the first hit found. */
inline bool KdTree_traverse(const KdTree *tree, float3 org, float3 dir,
                            float tmin, float tmax, bool any_hit, Hit *hit) {
    float3 inv_dir = 1.0f / dir;
    float ray_tmin = tmin;
    hit->t = tmax;
    hit->tri = -1;
    hit->u = hit->v = 0.0f;
    float seg_min = tmin, seg_max = tmax;
    if (!KdTree_clip_root(tree, org, inv_dir, &seg_min, &seg_max)) return false;
    int stack_node[KD_STACK_SIZE];
    float stack_min[KD_STACK_SIZE], stack_max[KD_STACK_SIZE];
    int top = 0;
    int node = 0;
    /* widen the root interval a little so grazing hits on the box are kept */
    seg_max = seg_max * 1.00001f + 1e-30f;
    while (true) {
        KdNode n = tree->nodes[node];
        if (n.axis != KD_LEAF) {
            float o = n.axis == 0 ? org.x : (n.axis == 1 ? org.y : org.z);
            float d = n.axis == 0 ? dir.x : (n.axis == 1 ? dir.y : dir.z);
            float id = n.axis == 0 ? inv_dir.x : (n.axis == 1 ? inv_dir.y : inv_dir.z);
            float t_split = (n.split - o) * id;
            bool below_first = (o < n.split) || (o == n.split && d <= 0.0f);
            int near_child = below_first ? node + 1 : n.child;
            int far_child = below_first ? n.child : node + 1;
            if (t_split > seg_max || t_split <= 0.0f) {
                node = near_child;
            } else if (t_split < seg_min) {
                node = far_child;
            } else {
                if (top < KD_STACK_SIZE) {
                    stack_node[top] = far_child;
                    stack_min[top] = t_split;
                    stack_max[top] = seg_max;
                    top++;
                }
                node = near_child;
                seg_max = t_split;
            }
            continue;
        }
        /* leaf: test its triangles against the whole ray interval */
        for (int i = 0; i < n.count; ++i) {
            int tri = tree->leaf_tris[n.child + i];
            float t, u, v;
            if (KdTree_triangle(org, dir, tree->verts[3 * tri].xyz,
                                tree->verts[3 * tri + 1].xyz,
                                tree->verts[3 * tri + 2].xyz, ray_tmin, hit->t,
                                &t, &u, &v)) {
                hit->t = t;
                hit->tri = tri;
                hit->u = u;
                hit->v = v;
                if (any_hit) return true;
            }
        }
        /* a hit inside this leaf's interval is the closest one */
        if (hit->tri >= 0 && hit->t <= seg_max * 1.00001f + 1e-30f) return true;
        if (top == 0) return hit->tri >= 0;
        top--;
        node = stack_node[top];
        seg_min = stack_min[top];
        seg_max = stack_max[top];
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
