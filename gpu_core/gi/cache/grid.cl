/* Uniform grid over points: each point's cell, the key it is grouped by
 * (gpu_core/gi/cache/grid.py). */
#include "device/launch.h"
#include "gi/cache/cache.h"

/* keys[i] = linear index of the cell holding points[i]. */
__kernel void Cache_grid_keys(const __global float4 *points, const int n, const float4 grid_origin,
                              const int4 grid_dims, __global uint *keys) {
    int i = Launch_global_id();
    if (i >= n) return;
    int3 c = Cache_grid_cell(points[i].xyz, grid_origin, grid_dims);
    keys[i] = (uint)((c.z * grid_dims.y + c.y) * grid_dims.x + c.x);
}
