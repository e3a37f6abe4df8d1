/* Positions into the cache's normalised frame (gpu_core/gi/cache/frame.py). */
#include "device/launch.h"

/* out = (p - (centre_high + centre_low)) / extent, w = 0. */
__kernel void Cache_normalise(const __global float4 *points, const int n, const float4 centre_high,
                              const float4 centre_low, const float extent, __global float4 *out) {
    int i = Launch_global_id();
    if (i >= n) return;
    float3 d = (points[i].xyz - centre_high.xyz) - centre_low.xyz;
    out[i] = (float4)(d / extent, 0.0f);
}
