/* Image textures: bilinear lookups with repeat wrap in the shared atlas. */
#ifndef GPUGI_TEXTURE_H
#define GPUGI_TEXTURE_H
#include "device/structs.h"

inline float4 Texture_texel(const __global float4 *atlas, TextureInfo t, int x, int y) {
    x = ((x % t.width) + t.width) % t.width;
    y = ((y % t.height) + t.height) % t.height;
    return atlas[t.offset + y * t.width + x];
}

/* Sample at uv (v = 0 is the bottom row, as Blender stores images):
 * bilinear (Linear), or the texel uv falls in (Closest). */
inline float4 Texture_sample(const __global float4 *atlas, const __global TextureInfo *infos, int id, float2 uv) {
    TextureInfo t = infos[id];
    /* wrap uv into [0, 1) first, so huge coordinates stay in integer range */
    float2 w = uv - floor(uv);
    if (t.closest) return Texture_texel(atlas, t, (int)(w.x * t.width), (int)(w.y * t.height));
    float fx = w.x * t.width - 0.5f, fy = w.y * t.height - 0.5f;
    int x0 = (int)floor(fx), y0 = (int)floor(fy);
    float ax = fx - x0, ay = fy - y0;
    float4 a = mix(Texture_texel(atlas, t, x0, y0), Texture_texel(atlas, t, x0 + 1, y0), ax);
    float4 b = mix(Texture_texel(atlas, t, x0, y0 + 1), Texture_texel(atlas, t, x0 + 1, y0 + 1), ax);
    return mix(a, b, ay);
}

/* The value a value socket (Roughness, Metallic) reads from texture id:
 * one channel, or the colour's luminance (TEXTURE_LUMINANCE), as Blender
 * converts a colour to a value. */
inline float Texture_value(const __global float4 *atlas, const __global TextureInfo *infos, int id, int channel,
                           float2 uv) {
    float4 c = Texture_sample(atlas, infos, id, uv);
    if (channel == TEXTURE_LUMINANCE) return dot(c.xyz, (float3)(0.2126f, 0.7152f, 0.0722f));
    return channel == 0 ? c.x : (channel == 1 ? c.y : (channel == 2 ? c.z : c.w));
}

#endif
