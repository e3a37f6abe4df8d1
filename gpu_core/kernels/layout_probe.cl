/* Reports the size and every named field offset of the shared structs, in
 * the order of their numpy twins in gpu_core/layout.py (padding skipped),
 * for tests/test_layout.py. The last entry is sizeof(float3). */
#include "types.h"

#define LAYOUT_OFFSET(T, f) ((int)((size_t) & (((T *)0)->f)))

__kernel void Layout_probe(__global int *out) {
    int i = 0;
    out[i++] = sizeof(KdNode);
    out[i++] = LAYOUT_OFFSET(KdNode, split);
    out[i++] = LAYOUT_OFFSET(KdNode, axis);
    out[i++] = LAYOUT_OFFSET(KdNode, child);
    out[i++] = LAYOUT_OFFSET(KdNode, count);

    out[i++] = sizeof(Material);
    out[i++] = LAYOUT_OFFSET(Material, base_color);
    out[i++] = LAYOUT_OFFSET(Material, emission);
    out[i++] = LAYOUT_OFFSET(Material, metallic);
    out[i++] = LAYOUT_OFFSET(Material, roughness);
    out[i++] = LAYOUT_OFFSET(Material, transmission);
    out[i++] = LAYOUT_OFFSET(Material, ior);
    out[i++] = LAYOUT_OFFSET(Material, texture);

    out[i++] = sizeof(Light);
    out[i++] = LAYOUT_OFFSET(Light, position);
    out[i++] = LAYOUT_OFFSET(Light, direction);
    out[i++] = LAYOUT_OFFSET(Light, axis_u);
    out[i++] = LAYOUT_OFFSET(Light, axis_v);
    out[i++] = LAYOUT_OFFSET(Light, power);
    out[i++] = LAYOUT_OFFSET(Light, radiance);
    out[i++] = LAYOUT_OFFSET(Light, radius);
    out[i++] = LAYOUT_OFFSET(Light, cos_half);
    out[i++] = LAYOUT_OFFSET(Light, spot_smooth);
    out[i++] = LAYOUT_OFFSET(Light, sun_norm);
    out[i++] = LAYOUT_OFFSET(Light, kind);
    out[i++] = LAYOUT_OFFSET(Light, shape);

    out[i++] = sizeof(Camera);
    out[i++] = LAYOUT_OFFSET(Camera, right);
    out[i++] = LAYOUT_OFFSET(Camera, up);
    out[i++] = LAYOUT_OFFSET(Camera, back);
    out[i++] = LAYOUT_OFFSET(Camera, origin);
    out[i++] = LAYOUT_OFFSET(Camera, window);
    out[i++] = LAYOUT_OFFSET(Camera, kind);
    out[i++] = LAYOUT_OFFSET(Camera, width);
    out[i++] = LAYOUT_OFFSET(Camera, height);
    out[i++] = LAYOUT_OFFSET(Camera, clip_start);
    out[i++] = LAYOUT_OFFSET(Camera, clip_end);

    out[i++] = sizeof(TextureInfo);
    out[i++] = LAYOUT_OFFSET(TextureInfo, offset);
    out[i++] = LAYOUT_OFFSET(TextureInfo, width);
    out[i++] = LAYOUT_OFFSET(TextureInfo, height);

    out[i++] = sizeof(float3);
}
