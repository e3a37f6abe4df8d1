/* Photon maps reweighted for a change of light power or colour alone: the
 * photons keep their paths (they depend on the surfaces, not on how bright
 * the lights are) and each photon's power is scaled by its emitter's new
 * power over the power it was traced with, per channel. The index of a
 * photon's emitter is in its power's w (photon_trace.cl). Every node of the
 * photon tree then sums its photons again: the power and the approximate
 * irradiance the illumination cut reads (accel/point_tree_build.cl). */
#include "device/launch.h"
#include "accel/point_tree.h"

/* Scale each photon (leaf order) by its emitter's row of `scales`. */
__kernel void PhotonReweight_scale(__global float4 *power, const __global float4 *scales, const int n_emitters,
                                   const int n) {
    int i = Launch_global_id();
    if (i >= n) return;
    float4 p = power[i];
    int e = clamp((int)p.w, 0, n_emitters - 1);
    power[i] = (float4)(p.xyz * scales[e].xyz, p.w);
}

/* A node's power and approximate irradiance from its photons again:
 * the subtree's points are [first, first + count) in leaf order, its size
 * r_p and normal n_p stay as built. */
__kernel void PhotonReweight_refit(__global PointNode *info, const __global float4 *power,
                                   const __global float4 *dir, const int n_nodes) {
    int id = Launch_global_id();
    if (id >= n_nodes) return;
    PointNode node = info[id];
    float3 sum = (float3)(0.0f), m0 = sum, m1 = sum, m2 = sum;
    for (int i = node.first; i < node.first + node.count; ++i) {
        float3 phi = power[i].xyz, w = dir[i].xyz;
        sum += phi;
        m0 += phi.x * w;
        m1 += phi.y * w;
        m2 += phi.z * w;
    }
    info[id].power = (float4)(sum, 0.0f);
    info[id].irradiance = (float4)(PointNode_irradiance(node.normal.xyz, node.lo.w, m0, m1, m2), 0.0f);
}
