/* Reports sizeof and field offsets of the shared structs, for the layout test. */
#include "types.h"

#define LAYOUT_OFFSET(T, f) ((int)((size_t) & (((T *)0)->f)))

__kernel void Layout_probe(__global int *out) {
    int i = 0;
    out[i++] = sizeof(KdNode);
    out[i++] = LAYOUT_OFFSET(KdNode, axis);
    out[i++] = LAYOUT_OFFSET(KdNode, child);
    out[i++] = LAYOUT_OFFSET(KdNode, count);
    out[i++] = sizeof(Material);
    out[i++] = LAYOUT_OFFSET(Material, emission);
    out[i++] = LAYOUT_OFFSET(Material, metallic);
    out[i++] = LAYOUT_OFFSET(Material, ior);
    out[i++] = LAYOUT_OFFSET(Material, texture);
    out[i++] = sizeof(Light);
    out[i++] = LAYOUT_OFFSET(Light, direction);
    out[i++] = LAYOUT_OFFSET(Light, power);
    out[i++] = LAYOUT_OFFSET(Light, kind);
    out[i++] = LAYOUT_OFFSET(Light, shape);
    out[i++] = LAYOUT_OFFSET(Light, pick_pdf);
    out[i++] = sizeof(Camera);
    out[i++] = LAYOUT_OFFSET(Camera, window);
    out[i++] = LAYOUT_OFFSET(Camera, kind);
    out[i++] = LAYOUT_OFFSET(Camera, width);
    out[i++] = LAYOUT_OFFSET(Camera, clip_start);
    out[i++] = LAYOUT_OFFSET(Camera, clip_end);
    out[i++] = sizeof(TextureInfo);
    out[i++] = sizeof(float3);
}
