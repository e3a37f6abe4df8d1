/* Lone outlier cache samples brought down to OUTLIER_RATIO times the median
 * luminance of their OUTLIER_NEIGHBOURS nearest samples (gpu_core/gi/cache/
 * outliers.py). Built with KNN_K = OUTLIER_NEIGHBOURS + 1 (the sample itself
 * comes first). */
#include "device/launch.h"
#include "accel/point_tree_knn.h"
#include "device/sampling.h"

/* Median of the first n values of v (sorted in place); 0 when n is 0. */
inline float Outliers_median(float *v, int n) {
    for (int i = 1; i < n; ++i) {
        float x = v[i];
        int j = i - 1;
        for (; j >= 0 && v[j] > x; --j) v[j + 1] = v[j];
        v[j + 1] = x;
    }
    if (n == 0) return 0.0f;
    return n % 2 ? v[n / 2] : 0.5f * (v[n / 2 - 1] + v[n / 2]);
}

/* Per sample j (tree over the sample positions): its nearest samples in
 * order, itself first; out[j] = irradiance[j] scaled down to the limit
 * where its luminance exceeds it. `clamped` counts them. */
__kernel void Outliers_clamp(POINT_TREE_PARAMS, const __global float4 *positions, const __global float4 *irradiance,
                             const int m, __global float4 *out, volatile __global int *clamped) {
    int j = Launch_global_id();
    if (j >= m) return;
    PointTree tree = POINT_TREE_MAKE();
    Knn h;
    PointTree_knn(&tree, positions[j].xyz, KNN_K, INFINITY, &h);
    /* the candidates by distance (then index), the sample itself first */
    int n = Knn_count(&h);
    Knn_sort(&h);
    float lum[KNN_K];
    int count = 0;
    for (int i = 1; i < n; ++i) {
        int id = as_int(tree.points[Knn_id(&h, i)].w);
        lum[count++] = Sampling_luminance(irradiance[id].xyz);
    }
    float limit = OUTLIER_RATIO * Outliers_median(lum, count);
    float4 e = irradiance[j];
    float own = Sampling_luminance(e.xyz);
    if (count > 0 && own > fmax(limit, 0.0f)) {
        e.xyz *= limit / fmax(own, 1e-30f);
        atomic_inc(clamped);
    }
    out[j] = e;
}
