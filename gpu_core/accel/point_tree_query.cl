/* Batch queries on the point kd-tree: k nearest neighbours, and irradiance
 * or Lambertian radiance by density estimation. Built with -D KNN_K=capacity
 * and KNN_VARIABLE_K: a launch passes its k, at most the capacity. */
#include "device/launch.h"
#include "accel/point_tree_knn.h"
#include "accel/point_density.h"

/* The k nearest points of each query, sorted by distance, as original
 * point indices; rows padded with -1 and INFINITY. Work item i handles
 * query order[i] (a spatially coherent order) and writes that row. */
__kernel void PointTree_knn_batch(POINT_TREE_PARAMS, const __global float4 *queries,
                                  const __global int *order, const float max_d2, const int k,
                                  const int n_queries, __global int *out_id,
                                  __global float *out_d2) {
    int i = Launch_global_id();
    if (i >= n_queries) return;
    int q = order[i];
    PointTree tree = POINT_TREE_MAKE();
    Knn h;
    PointTree_knn(&tree, queries[q].xyz, k, max_d2, &h);
    size_t row = (size_t)q * k;
    int n = Knn_count(&h);
    Knn_sort(&h);
    for (int j = 0; j < k; ++j) {
        out_id[row + j] = j < n ? as_int(tree.points[Knn_id(&h, j)].w) : -1;
        out_d2[row + j] = j < n ? Knn_d2(&h, j) : INFINITY;
    }
}

/* Irradiance at each query point (xyz) with its unit normal or, with
 * as_radiance set, the radiance albedo / pi * E of a Lambertian surface.
 * Work item i handles query order[i], or query i without an order. */
__kernel void PointTree_density_batch(POINT_TREE_PARAMS, PHOTON_PARAMS,
                                      const __global float4 *queries,
                                      const __global float4 *normals,
                                      const __global float4 *albedo,
                                      const __global int *order, const float max_d2, const int k,
                                      const int filter, const float normal_cos,
                                      const int as_radiance, const int n_queries,
                                      __global float4 *out) {
    int i = Launch_global_id();
    if (i >= n_queries) return;
    int q = order ? order[i] : i;
    PointTree tree = POINT_TREE_MAKE();
    PhotonData ph = PHOTON_DATA_MAKE();
    float3 e = Density_irradiance(&tree, &ph, queries[q].xyz, normals[q].xyz, k, max_d2, filter, normal_cos);
    if (as_radiance) e *= albedo[q].xyz * (1.0f / PI_F);
    out[q] = (float4)(e, 0.0f);
}
