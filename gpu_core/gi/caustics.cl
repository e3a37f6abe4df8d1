/* Caustics seen directly: the caustic map's density estimate on the shading
 * points' grid (gi/caustics.py). Anchor slots, those of the pixels on a
 * lattice a few pixels apart, are estimated from their k nearest photons;
 * then, level by level, each lattice half as far apart fills its new slots
 * with the mean of the slots beside them on the level before (two in a row
 * or column, or the four around) where those all lie on the slot's surface
 * well inside their estimates' radius, and with the slot's own estimate
 * elsewhere. Built with the photon searches' defines (KNN_K,
 * KNN_VARIABLE_K). */
#include "device/launch.h"
#include "accel/point_density.h"

/* The estimate at x with unit normal n (rgb) and its squared radius (w). */
inline float4 Caustics_estimate(const PointTree *tree, const PhotonData *ph, float3 x, float3 n, int k,
                                float max_d2, int filter, float normal_cos) {
    Knn h;
    PointTree_knn(tree, x, k, max_d2, &h);
    float3 e = Density_irradiance_from(&h, ph, n, max_d2, filter, normal_cos);
    return (float4)(e, Density_radius2(&h, max_d2));
}

/* The slot of sub-position s of pixel (x, y) of a window `width` wide. */
inline int Caustics_slot(int x, int y, int s, int width, int sub2) { return (y * width + x) * sub2 + s; }

/* Work-item i's slot on the lattice of pixels `spacing` apart (sub-position
 * i % sub2 of its (i / sub2)-th pixel, row by row), or -1 past its end. */
inline int Caustics_lattice_slot(int i, int spacing, int width, int height, int sub2, int *x, int *y) {
    int across = (width + spacing - 1) / spacing, a = i / sub2;
    if (a >= across * ((height + spacing - 1) / spacing)) return -1;
    *x = spacing * (a % across);
    *y = spacing * (a / across);
    return Caustics_slot(*x, *y, i % sub2, width, sub2);
}

/* Per anchor slot (the lattice of pixels `spacing` apart): its estimate and
 * squared radius, or zero where the slot holds no point. */
__kernel void Caustics_anchors(POINT_TREE_PARAMS, PHOTON_PARAMS, const __global float4 *grid_pos,
                               const __global float4 *grid_nrm, const int width, const int height, const int sub2,
                               const float max_d2, const int k, const int filter, const float normal_cos,
                               const int spacing, __global float4 *out) {
    int x, y;
    int slot = Caustics_lattice_slot(Launch_global_id(), spacing, width, height, sub2, &x, &y);
    if (slot < 0) return;
    float4 p = grid_pos[slot];
    if (!(p.w > 0.0f)) {
        out[slot] = (float4)(0.0f);
        return;
    }
    PointTree tree = POINT_TREE_MAKE();
    PhotonData ph = PHOTON_DATA_MAKE();
    out[slot] = Caustics_estimate(&tree, &ph, p.xyz, grid_nrm[slot].xyz, k, max_d2, filter, normal_cos);
}

/* Per slot of the lattice of pixels step / 2 apart that is not on the
 * lattice of `step` (whose slots hold estimates and squared radii, zero
 * without a point): the mean of those beside it (step before and after it
 * in its row, its column, or both) where each lies inside the window, its
 * normal within acos(same_cos) of the slot's and its point within span
 * times its estimate's radius of the slot's; else the slot's own estimate
 * and radius; zero where the slot holds no point. An interpolated slot's
 * radius is the smallest of its anchors' less their distance to it, so
 * that a finer level interpolating from it stays within span of a radius. */
__kernel void Caustics_fill(POINT_TREE_PARAMS, PHOTON_PARAMS, const __global float4 *grid_pos,
                            const __global float4 *grid_nrm, const int width, const int height, const int sub2,
                            const float max_d2, const int k, const int filter, const float normal_cos,
                            const int step, const float span, const float same_cos, __global float4 *out) {
    int x, y;
    int slot = Caustics_lattice_slot(Launch_global_id(), step / 2, width, height, sub2, &x, &y);
    if (slot < 0 || (x % step == 0 && y % step == 0)) return;
    float4 p = grid_pos[slot];
    if (!(p.w > 0.0f)) {
        out[slot] = (float4)(0.0f);
        return;
    }
    float3 n = grid_nrm[slot].xyz;
    int x0 = x - x % step, y0 = y - y % step, nx = x % step ? 2 : 1, ny = y % step ? 2 : 1;
    bool near = x0 + step * (nx - 1) < width && y0 + step * (ny - 1) < height;
    float3 sum = (float3)(0.0f);
    float reach = INFINITY;
    for (int j = 0; near && j < ny; ++j) {
        for (int m = 0; near && m < nx; ++m) {
            int at = Caustics_slot(x0 + step * m, y0 + step * j, slot % sub2, width, sub2);
            float4 q = grid_pos[at], e = out[at];
            float d = distance(q.xyz, p.xyz), r = sqrt(e.w);
            near = dot(grid_nrm[at].xyz, n) >= same_cos && d <= span * r; /* r = 0 without a point */
            sum += e.xyz;
            reach = fmin(reach, r - d);
        }
    }
    if (near) {
        out[slot] = (float4)(sum / (float)(nx * ny), reach * reach);
        return;
    }
    PointTree tree = POINT_TREE_MAKE();
    PhotonData ph = PHOTON_DATA_MAKE();
    out[slot] = Caustics_estimate(&tree, &ph, p.xyz, n, k, max_d2, filter, normal_cos);
}
