/* Reports the size and every named field offset of the photon-map structs,
 * in the order of their numpy twins in gpu_core/photons/layout.py (padding
 * skipped), for tests/test_point_tree.py. */
#include "point_tree_build.cl"
#include "photon_emit.h"

#define LAYOUT_OFFSET(T, f) ((int)((size_t) & (((T *)0)->f)))

__kernel void PointTree_layout_probe(__global int *out) {
    int i = 0;
    out[i++] = sizeof(PointNode);
    out[i++] = LAYOUT_OFFSET(PointNode, lo);
    out[i++] = LAYOUT_OFFSET(PointNode, hi);
    out[i++] = LAYOUT_OFFSET(PointNode, power);
    out[i++] = LAYOUT_OFFSET(PointNode, irradiance);
    out[i++] = LAYOUT_OFFSET(PointNode, normal);
    out[i++] = LAYOUT_OFFSET(PointNode, first);
    out[i++] = LAYOUT_OFFSET(PointNode, count);
    out[i++] = LAYOUT_OFFSET(PointNode, depth);

    out[i++] = sizeof(BuildNode);
    out[i++] = LAYOUT_OFFSET(BuildNode, lo);
    out[i++] = LAYOUT_OFFSET(BuildNode, hi);
    out[i++] = LAYOUT_OFFSET(BuildNode, start);
    out[i++] = LAYOUT_OFFSET(BuildNode, count);
    out[i++] = LAYOUT_OFFSET(BuildNode, mask);
    out[i++] = LAYOUT_OFFSET(BuildNode, root);
    out[i++] = LAYOUT_OFFSET(BuildNode, left);
    out[i++] = LAYOUT_OFFSET(BuildNode, axis);
    out[i++] = LAYOUT_OFFSET(BuildNode, split);
    out[i++] = LAYOUT_OFFSET(BuildNode, depth);

    out[i++] = sizeof(Chunk);
    out[i++] = LAYOUT_OFFSET(Chunk, slot);
    out[i++] = LAYOUT_OFFSET(Chunk, start);
    out[i++] = LAYOUT_OFFSET(Chunk, count);
    out[i++] = LAYOUT_OFFSET(Chunk, rank);

    out[i++] = sizeof(BuildSums);
    out[i++] = LAYOUT_OFFSET(BuildSums, lo);
    out[i++] = LAYOUT_OFFSET(BuildSums, hi);
    out[i++] = LAYOUT_OFFSET(BuildSums, power);
    out[i++] = LAYOUT_OFFSET(BuildSums, normal);
    out[i++] = LAYOUT_OFFSET(BuildSums, moment);

    out[i++] = sizeof(PhotonEmitter);
    out[i++] = LAYOUT_OFFSET(PhotonEmitter, power);
    out[i++] = LAYOUT_OFFSET(PhotonEmitter, light);
    out[i++] = LAYOUT_OFFSET(PhotonEmitter, first);
    out[i++] = LAYOUT_OFFSET(PhotonEmitter, count);
}
