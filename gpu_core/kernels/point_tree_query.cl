/* Batch queries on the point kd-tree: k nearest neighbours, and irradiance
 * or Lambertian radiance by density estimation. Built with -D KNN_K=k. */
#include "point_tree_knn.h"
#include "photon_density.h"

/* The k nearest points of each query, sorted by distance, as original
 * point indices; rows padded with -1 and INFINITY. Work item i handles
 * query order[i] (a spatially coherent order) and writes that row. */
__kernel void PointTree_knn_batch(POINT_TREE_PARAMS, const __global float4 *queries,
                                  const __global int *order, const float max_d2,
                                  const int n_queries, __global int *out_id,
                                  __global float *out_d2) {
    int i = get_global_id(0);
    if (i >= n_queries) return;
    int q = order[i];
    PointTree tree = POINT_TREE_MAKE();
    Knn h;
    PointTree_knn(&tree, queries[q].xyz, max_d2, &h);
    size_t row = (size_t)q * KNN_K;
    int n = Knn_count(&h);
    for (int j = n; j < KNN_K; ++j) {
        out_id[row + j] = -1;
        out_d2[row + j] = INFINITY;
    }
    /* heap sort straight into the row: the farthest left goes last */
    if (n < KNN_K) Knn_heapify(&h, n);
    for (int end = n - 1; end >= 0; --end) {
        out_id[row + end] = as_int(tree.points[Knn_id(&h, 0)].w);
        out_d2[row + end] = Knn_d2(&h, 0);
        if (end > 0) Knn_sift(&h, 0, end, h.key[end]);
    }
}

/* Irradiance at each query point (xyz) with its unit normal or, with
 * as_radiance set, the radiance albedo / pi * E of a Lambertian surface.
 * Work item i handles query order[i]. */
__kernel void PointTree_density_batch(POINT_TREE_PARAMS, PHOTON_PARAMS,
                                      const __global float4 *queries,
                                      const __global float4 *normals,
                                      const __global float4 *albedo,
                                      const __global int *order, const float max_d2,
                                      const int filter, const float normal_cos,
                                      const int as_radiance, const int n_queries,
                                      __global float4 *out) {
    int i = get_global_id(0);
    if (i >= n_queries) return;
    int q = order[i];
    PointTree tree = POINT_TREE_MAKE();
    PhotonData ph = PHOTON_DATA_MAKE();
    float3 e = Photon_irradiance(&tree, &ph, queries[q].xyz, normals[q].xyz, max_d2, filter,
                                 normal_cos);
    if (as_radiance) e *= albedo[q].xyz * (1.0f / PI_F);
    out[q] = (float4)(e, 0.0f);
}
