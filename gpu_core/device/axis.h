/* One coordinate of a vector by axis number (0 x, 1 y, 2 z), read or set:
 * the kd-tree builders and traversals choose planes by axis. */
#ifndef GPUGI_AXIS_H
#define GPUGI_AXIS_H

inline float Axis_of3(float3 v, int axis) {
    return axis == 0 ? v.x : (axis == 1 ? v.y : v.z);
}

inline float Axis_of(float4 v, int axis) {
    return axis == 0 ? v.x : (axis == 1 ? v.y : v.z);
}

inline float4 Axis_with(float4 v, int axis, float value) {
    if (axis == 0) v.x = value;
    else if (axis == 1) v.y = value;
    else v.z = value;
    return v;
}

#endif
