/* Sampling of directions and shapes used by lights, BSDFs and the camera. */
#ifndef GPUGI_SAMPLING_H
#define GPUGI_SAMPLING_H

#define PI_F 3.14159265358979f

/* Two unit vectors t, b completing n to an orthonormal frame. */
inline void Sampling_frame(float3 n, float3 *t, float3 *b) {
    float s = n.z >= 0.0f ? 1.0f : -1.0f;
    float a = -1.0f / (s + n.z);
    float c = n.x * n.y * a;
    *t = (float3)(1.0f + s * n.x * n.x * a, s * c, -s * n.x);
    *b = (float3)(c, s + n.y * n.y * a, -n.y);
}

/* (cos, sin) of a sampled angle: the native functions where the device's
 * are accurate to a few ulp (PoCL; programs.py defines GPUGI_NATIVE_TRIG
 * there), at a third of the accurate ones' cost; the accurate ones
 * elsewhere (Intel's CPU runtime's native pair errs by 1.5e-4, which left
 * cosine-sampled directions in the surface's plane). */
inline float2 Sampling_cos_sin(float x) {
#ifdef GPUGI_NATIVE_TRIG
    return (float2)(native_cos(x), native_sin(x));
#else
    return (float2)(cos(x), sin(x));
#endif
}

/* (cos, sin) of the angle 2 pi u of a sample. */
inline float2 Sampling_turn(float u) {
    return Sampling_cos_sin(2.0f * PI_F * u);
}

/* Point in the unit disk (polar mapping). */
inline float2 Sampling_disk(float u1, float u2) {
    return sqrt(u1) * Sampling_turn(u2);
}

/* Cosine-distributed direction around +z: the disk point lifted to the
 * hemisphere, its height sqrt(1 - u1) from the sample itself (1 - r^2 of
 * the rounded disk point cancels to 0 at the rim: a direction in the
 * surface's plane, which no pdf accepts). Above the plane for every u1 < 1. */
inline float3 Sampling_cosine_local(float u1, float u2) {
    float2 d = Sampling_disk(u1, u2);
    return (float3)(d.x, d.y, sqrt(fmax(0.0f, 1.0f - u1)));
}

/* Cosine-distributed direction around n. */
inline float3 Sampling_cosine(float3 n, float u1, float u2) {
    float3 t, b;
    Sampling_frame(n, &t, &b);
    float3 d = Sampling_cosine_local(u1, u2);
    return normalize(d.x * t + d.y * b + d.z * n);
}

/* Uniform direction in the cone around axis with cos(half angle) cos_max. */
inline float3 Sampling_cone(float3 axis, float cos_max, float u1, float u2) {
    float3 t, b;
    Sampling_frame(axis, &t, &b);
    float cos_t = 1.0f - u1 * (1.0f - cos_max);
    float sin_t = sqrt(fmax(0.0f, 1.0f - cos_t * cos_t));
    float2 turn = sin_t * Sampling_turn(u2);
    return normalize(turn.x * t + turn.y * b + cos_t * axis);
}

/* Uniform point in a triangle as barycentrics (u, v). */
inline float2 Sampling_triangle(float u1, float u2) {
    float s = sqrt(u1);
    return (float2)(1.0f - s, u2 * s);
}

/* Rec. 709 luminance. */
inline float Sampling_luminance(float3 c) {
    return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z;
}

#endif
