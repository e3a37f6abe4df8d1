/* Next-event estimation for every light type, in Cycles' units.
 * Each sampler returns an estimate of the irradiance the light gives the
 * point x with normal n (receiver cosine included), the direction towards
 * the sampled light point, and the shadow-ray length. */
#ifndef GPUGI_LIGHTS_H
#define GPUGI_LIGHTS_H
#include "types.h"
#include "sampling.h"

#define LIGHT_FAR 3.0e38f

typedef struct {
    float3 dir;   /* unit, from x towards the light */
    float dist;   /* shadow ray length; LIGHT_FAR for sun and world */
    float3 value; /* irradiance estimate (W/m^2), receiver cosine included */
} LightSample;

/* Emissive triangles chosen by a power CDF (one light of kind LIGHT_MESH). */
typedef struct {
    const __global int *tris;   /* emissive triangle ids */
    const __global float *cdf;  /* inclusive CDF over tris, last = 1 */
    int count;
    const __global float4 *verts;
    const __global int *tri_material;
    const __global Material *materials;
} Emitters;

/* Cycles' spot cone: smoothstep over the blend width, no cosine term. */
inline float Light_spot_attenuation(const Light *l, float3 from_light) {
    float c = dot(from_light, l->direction.xyz);
    float x = (c - l->direction.w) * l->axis_u.w;
    x = clamp(x, 0.0f, 1.0f);
    return x * x * (3.0f - 2.0f * x);
}

/* Point and spot lights: a sphere of radius r seen as a disk facing x;
 * irradiance P / (4 pi d^2) cos at distance d. */
inline LightSample Light_sample_point(const Light *l, float3 x, float3 n, float u1, float u2) {
    LightSample s;
    float3 c = l->position.xyz;
    float3 to_c = c - x;
    float d_c = length(to_c);
    float3 axis = d_c > 0.0f ? to_c / d_c : (float3)(0.0f, 0.0f, 1.0f);
    float3 y = c;
    if (l->position.w > 0.0f) {
        float3 t, b;
        Sampling_frame(axis, &t, &b);
        float2 dk = Sampling_disk(u1, u2) * l->position.w;
        y = c + dk.x * t + dk.y * b;
    }
    float3 to_y = y - x;
    float d2 = fmax(dot(to_y, to_y), 1e-30f);
    float d = sqrt(d2);
    s.dir = to_y / d;
    s.dist = d;
    float cos_x = fmax(0.0f, dot(n, s.dir));
    float atten = l->kind == LIGHT_SPOT ? Light_spot_attenuation(l, -axis) : 1.0f;
    s.value = l->power.xyz * (atten * cos_x / (4.0f * PI_F * d2));
    return s;
}

/* Sun: a disk of directions of angular diameter `angle`; irradiance S cos. */
inline LightSample Light_sample_sun(const Light *l, float3 n, float u1, float u2) {
    LightSample s;
    float3 toward = -l->direction.xyz;
    s.dir = l->axis_v.w < 1.0f ? Sampling_cone(toward, l->axis_v.w, u1, u2) : toward;
    s.dist = LIGHT_FAR;
    s.value = l->power.xyz * fmax(0.0f, dot(n, s.dir));
    return s;
}

/* Area light: rectangle or ellipse emitting along its direction, radiance
 * P / (pi A), sampled uniformly by area. */
inline LightSample Light_sample_area(const Light *l, float3 x, float3 n, float u1, float u2) {
    LightSample s;
    float2 q;
    if (l->shape == 1) {
        q = 0.5f * Sampling_disk(u1, u2);
    } else {
        q = (float2)(u1 - 0.5f, u2 - 0.5f);
    }
    float3 y = l->position.xyz + q.x * l->axis_u.xyz + q.y * l->axis_v.xyz;
    float3 to_y = y - x;
    float d2 = fmax(dot(to_y, to_y), 1e-30f);
    float d = sqrt(d2);
    s.dir = to_y / d;
    s.dist = d;
    float cos_x = fmax(0.0f, dot(n, s.dir));
    float cos_y = fmax(0.0f, -dot(l->direction.xyz, s.dir));
    /* radiance P/(pi A) times the area-sampling Jacobian A cos_y / d^2 */
    s.value = l->power.xyz * (cos_x * cos_y / (PI_F * d2));
    return s;
}

/* Emissive triangles: pick one by power, a uniform point on it; both faces
 * emit their material's radiance. */
inline LightSample Light_sample_mesh(const Emitters *em, float3 x, float3 n, float u0, float u1, float u2) {
    LightSample s;
    int lo = 0, hi = em->count - 1;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (em->cdf[mid] <= u0) lo = mid + 1; else hi = mid;
    }
    float prev = lo > 0 ? em->cdf[lo - 1] : 0.0f;
    float pick = fmax(em->cdf[lo] - prev, 1e-30f);
    int tri = em->tris[lo];
    float3 v0 = em->verts[3 * tri].xyz, v1 = em->verts[3 * tri + 1].xyz, v2 = em->verts[3 * tri + 2].xyz;
    float2 bc = Sampling_triangle(u1, u2);
    float3 y = v0 + bc.x * (v1 - v0) + bc.y * (v2 - v0);
    float3 cr = cross(v1 - v0, v2 - v0);
    float area = 0.5f * length(cr);
    float3 ny = cr / fmax(2.0f * area, 1e-30f);
    float3 to_y = y - x;
    float d2 = fmax(dot(to_y, to_y), 1e-30f);
    float d = sqrt(d2);
    s.dir = to_y / d;
    s.dist = d;
    float cos_x = fmax(0.0f, dot(n, s.dir));
    float cos_y = fabs(dot(ny, s.dir));
    float3 le = em->materials[em->tri_material[tri]].emission.xyz;
    s.value = le * (cos_x * cos_y * area / (d2 * pick));
    return s;
}

/* Uniform world of radiance L: cosine sampling gives the estimate pi L. */
inline LightSample Light_sample_world(float3 world, float3 n, float u1, float u2) {
    LightSample s;
    s.dir = Sampling_cosine(n, u1, u2);
    s.dist = LIGHT_FAR;
    s.value = PI_F * world;
    return s;
}

/* One sample of light l (sun, point, spot, area, mesh). */
inline LightSample Light_sample(const Light *l, const Emitters *em, float3 x, float3 n, float u0, float u1, float u2) {
    if (l->kind == LIGHT_SUN) return Light_sample_sun(l, n, u1, u2);
    if (l->kind == LIGHT_AREA) return Light_sample_area(l, x, n, u1, u2);
    if (l->kind == LIGHT_MESH) return Light_sample_mesh(em, x, n, u0, u1, u2);
    return Light_sample_point(l, x, n, u1, u2);
}

#endif
