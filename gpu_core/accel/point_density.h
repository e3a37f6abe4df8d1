/* Density estimation of irradiance from the k nearest photons.
 * E(x) = sum_i Phi_i K(d_i / r) over the photons that arrived on the front
 * of the surface at x, with r the distance to the k-th photon (or the
 * search radius when fewer were found) and K a 2D filter whose integral
 * over the disk of radius r is one. */
#ifndef GPUGI_POINT_DENSITY_H
#define GPUGI_POINT_DENSITY_H
#include "accel/point_tree_knn.h"
#include "device/sampling.h"

/* Filters (PHOTON_FILTER_*, device/constants.py): box; Jensen's cone, k = 1;
 * Epanechnikov, 1 - t^2. */

/* Filter weight at t = d / r in [0, 1], times r^2 (normalised on the disk). */
inline float Density_filter(int filter, float t) {
    if (filter == PHOTON_FILTER_CONE) return (3.0f / PI_F) * (1.0f - t);
    if (filter == PHOTON_FILTER_EPANECHNIKOV) return (2.0f / PI_F) * (1.0f - t * t);
    return 1.0f / PI_F;
}

/* Squared radius of the estimate: the k-th distance when k photons were
 * found, else the search radius, else the farthest photon found. */
inline float Density_radius2(const Knn *h, float max_d2) {
    float far = 0.0f;
    for (int i = 0; i < Knn_count(h); ++i) far = fmax(far, Knn_d2(h, i));
    return Knn_count(h) == Knn_wanted(h) || isinf(max_d2) ? far : max_d2;
}

/* Irradiance (rgb, W/m^2) at x on a surface with unit normal n from the
 * photons in h. Photons arriving from behind, or stored on a surface facing
 * away by more than acos(normal_cos), do not count. */
inline float3 Density_irradiance_from(const Knn *h, const PhotonData *ph, float3 n, float max_d2,
                                     int filter, float normal_cos) {
    float r2 = Density_radius2(h, max_d2);
    float3 e = (float3)(0.0f);
    if (!(r2 > 0.0f) || isinf(r2)) return e;
    float inv_r2 = 1.0f / r2;
    for (int i = 0; i < Knn_count(h); ++i) {
        int p = Knn_id(h, i);
        if (dot(ph->dir[p].xyz, n) <= 0.0f) continue;
        if (dot(ph->normal[p].xyz, n) < normal_cos) continue;
        float t = sqrt(fmin(Knn_d2(h, i) * inv_r2, 1.0f));
        e += ph->power[p].xyz * Density_filter(filter, t);
    }
    e *= inv_r2;
    /* a radius far below the photons' power range could overflow */
    if (!(isfinite(e.x) && isfinite(e.y) && isfinite(e.z))) e = (float3)(0.0f);
    return e;
}

/* kNN search and density estimate in one call. */
inline float3 Density_irradiance(const PointTree *tree, const PhotonData *ph, float3 x, float3 n, int k,
                                float max_d2, int filter, float normal_cos) {
    Knn h;
    PointTree_knn(tree, x, k, max_d2, &h);
    return Density_irradiance_from(&h, ph, n, max_d2, filter, normal_cos);
}

#endif
