/* The illumination cut of a photon tree [WZPB09], selected on the device
 * (gpu_core/gi/cut.py): the first node on every root-to-leaf path whose
 * approximate irradiance reaches E_min, refined by exact k-nearest
 * estimates; and a batch lookup of the irradiance it gives (cut_lookup.h).
 * A node's "mixed" flag: its photons lie on surfaces facing different ways
 * (|mean photon normal| below CUT_COHERENT) while it has children. */
#include "device/launch.h"
#include "accel/point_density.h"
#include "gi/cut_lookup.h"

/* CUT_COHERENT comes from the host (gpu_core/gi/cut.py). */

inline float Cut_approx(const __global PointNode *info, int i) {
    return Sampling_luminance(info[i].irradiance.xyz);
}

inline bool Cut_mixed(const __global KdNode *nodes, const __global PointNode *info, int i) {
    return nodes[i].axis != KD_LEAF && info[i].normal.w < CUT_COHERENT;
}

/* parent[child] for both children of every inner node (the root keeps -1). */
__kernel void Cut_parents(const __global KdNode *nodes, const int n, __global int *parent) {
    int i = Launch_global_id();
    if (i >= n || nodes[i].axis == KD_LEAF) return;
    parent[i + 1] = i;
    parent[nodes[i].child] = i;
}

/* Whether node i is marked for the coarse cut: approximate irradiance at
 * least E_min, not mixed, and at most max_photons photons. */
inline bool Cut_marked(const __global KdNode *nodes, const __global PointNode *info, int i, float e_min,
                       int max_photons) {
    return Cut_approx(info, i) >= e_min && !Cut_mixed(nodes, info, i) && info[i].count <= max_photons;
}

/* The coarse cut: a node is in it when it is marked or a leaf, and no
 * ancestor is marked. Empty nodes have their exact irradiance known: none. */
__kernel void Cut_coarse(const __global KdNode *nodes, const __global PointNode *info,
                         const __global int *parent, const int n, const float e_min, const int max_photons,
                         __global int *in_cut, __global float4 *exact) {
    int i = Launch_global_id();
    if (i >= n) return;
    bool marked = Cut_marked(nodes, info, i, e_min, max_photons);
    bool covered = false;
    for (int a = parent[i]; a >= 0 && !covered; a = parent[a])
        covered = Cut_marked(nodes, info, a, e_min, max_photons);
    in_cut[i] = (marked || nodes[i].axis == KD_LEAF) && !covered;
    exact[i] = info[i].count == 0 ? (float4)(0.0f, 0.0f, 0.0f, 1.0f) : (float4)(0.0f);
}

/* Exact irradiance (w = 1: known) of every cut node not known yet, by
 * density estimation of the k nearest photons at its photons' mean position
 * with its normal (+Z where unknown). */
__kernel void Cut_exact(POINT_TREE_PARAMS, PHOTON_PARAMS, const __global PointNode *info,
                        const __global int *in_cut, const int n, const int k, __global float4 *exact) {
    int i = Launch_global_id();
    if (i >= n || !in_cut[i] || exact[i].w > 0.0f) return;
    PointTree tree = POINT_TREE_MAKE();
    PhotonData ph = PHOTON_DATA_MAKE();
    float3 normal = info[i].normal.xyz;
    float len = length(normal);
    normal = len > 0.0f ? normal / len : (float3)(0.0f, 0.0f, 1.0f);
    float3 e = Density_irradiance(&tree, &ph, info[i].mean.xyz, normal, k, INFINITY, PHOTON_FILTER_EPANECHNIKOV, 0.5f);
    exact[i] = (float4)(e, 1.0f);
}

/* One refinement round: an inner cut node whose approximate irradiance
 * differs from the exact one by more than delta of it, or that is mixed,
 * leaves the cut for its two children; `refined` counts them. The round
 * reads `in_cut` and writes the next cut into `next` (a copy of it made
 * before), so no work-item reads a flag another one writes. */
__kernel void Cut_split(const __global KdNode *nodes, const __global PointNode *info, const __global float4 *exact,
                        const int n, const float delta, const __global int *in_cut, __global int *next,
                        volatile __global int *refined) {
    int i = Launch_global_id();
    if (i >= n || !in_cut[i] || nodes[i].axis == KD_LEAF || !(exact[i].w > 0.0f)) return;
    float e = Sampling_luminance(exact[i].xyz);
    if (!(fabs(Cut_approx(info, i) - e) > delta * e || Cut_mixed(nodes, info, i))) return;
    next[i] = 0;
    next[i + 1] = 1;
    next[nodes[i].child] = 1;
    atomic_inc(refined);
}

/* A cut node's row (node j of the cut is preorder node ids[j]): its
 * photons' mean position with its size L_j in w (the box's largest side,
 * at least r_p), normal, and exact irradiance (finite, not negative). */
__kernel void Cut_emit(const __global PointNode *info, const __global float4 *exact, const __global int *ids,
                       const int count, __global float4 *centre, __global float4 *normal,
                       __global float4 *irradiance) {
    int j = Launch_global_id();
    if (j >= count) return;
    PointNode nd = info[ids[j]];
    float3 extent = nd.hi.xyz - nd.lo.xyz;
    float size = fmax(fmax(fmax(extent.x, extent.y), extent.z), nd.lo.w);
    centre[j] = (float4)(nd.mean.xyz, size);
    normal[j] = (float4)(nd.normal.xyz, 0.0f);
    float3 e = exact[ids[j]].xyz;
    e = (float3)(isfinite(e.x) ? e.x : 0.0f, isfinite(e.y) ? e.y : 0.0f, isfinite(e.z) ? e.z : 0.0f);
    irradiance[j] = (float4)(fmax(e, (float3)(0.0f)), 0.0f);
}

/* Irradiance from the cut at a batch of surface points (float4 positions
 * and unit normals). */
__kernel void Cut_lookup(CUT_PARAMS, const __global float4 *points, const __global float4 *normals, const int n,
                         __global float4 *out) {
    int i = Launch_global_id();
    if (i >= n) return;
    Cut cut = CUT_MAKE();
    out[i] = (float4)(CutLookup_irradiance(&cut, points[i].xyz, normals[i].xyz), 0.0f);
}

/* Each node's irradiance plus its caustic estimate (the cut gathering reads). */
__kernel void Cut_add_irradiance(const __global float4 *irradiance, const __global float4 *caustic, const int n,
                                 __global float4 *out) {
    int i = Launch_global_id();
    if (i < n) out[i] = (float4)(irradiance[i].xyz + caustic[i].xyz, 0.0f);
}

/* ---- inputs of the host's reductions -------------------------------------- */

/* Each node's depth (x), for the deepest level. */
__kernel void Cut_depths(const __global PointNode *info, const int n, __global int4 *out) {
    int i = Launch_global_id();
    if (i < n) out[i] = (int4)(info[i].depth, 0, 0, 0);
}

/* (E~_p luminance, 0, 1, 0) of the lit nodes on levels a and b, else 0: summed, E_min's numerator and count. */
__kernel void Cut_level_terms(const __global PointNode *info, const int n, const int a, const int b,
                              __global float4 *out) {
    int i = Launch_global_id();
    if (i >= n) return;
    float e = Cut_approx(info, i);
    bool on = (info[i].depth == a || info[i].depth == b) && e > 0.0f;
    out[i] = on ? (float4)(e, 0.0f, 1.0f, 0.0f) : (float4)(0.0f);
}

/* 1 for a cut node that holds photons (empty leaves end their paths but give no light). */
__kernel void Cut_kept(const __global int *in_cut, const __global PointNode *info, const int n, __global int *flags) {
    int i = Launch_global_id();
    if (i < n) flags[i] = in_cut[i] != 0 && info[i].count > 0;
}

/* (in the cut, a leaf in the cut holding photons, mixed, 0) per node, for the statistics. */
__kernel void Cut_tally(const __global KdNode *nodes, const __global PointNode *info, const __global int *in_cut,
                        const int n, __global int4 *out) {
    int i = Launch_global_id();
    if (i >= n) return;
    bool cut = in_cut[i] != 0;
    out[i] = (int4)(cut, cut && info[i].count > 0 && nodes[i].axis == KD_LEAF, Cut_mixed(nodes, info, i), 0);
}
