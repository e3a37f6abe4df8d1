/* Photon emission from every light kind, in the units of lights.h, so the
 * photons of one light carry its whole emitted power in watts:
 *   point:  P, uniform over the sphere of directions from its centre;
 *   spot:   P/(4 pi) times the cone falloff, directions uniform in the cone;
 *   sun:    S pi R^2 through a disk of radius R facing the sun, covering the
 *           scene's bounding sphere, directions uniform in the sun's cone;
 *   area:   P, a uniform point on the shape, cosine-weighted around -Z;
 *   mesh:   2 pi A L_e per triangle (both faces), a triangle by the power
 *           CDF, a uniform point, a face, a cosine-weighted direction;
 *   world:  4 pi^2 R^2 L, a uniform direction and a uniform point on the
 *           disk of the bounding sphere facing it.
 * The host splits the photons over emitters in proportion to power
 * (gpu_core/photons/emit.py) and gives each emitter its power per photon
 * (PhotonEmitter, device/structs.h). */
#ifndef GPUGI_PHOTON_EMIT_H
#define GPUGI_PHOTON_EMIT_H
#include "device/rng.h"
#include "device/sampling.h"
#include "device/ray.h"
#include "shading/lights.h"

/* A photon leaving its emitter. */
typedef struct {
    float3 org;
    float3 dir;
    float3 power;
} PhotonRay;

/* Uniform direction on the unit sphere. */
inline float3 PhotonEmit_sphere(float u1, float u2) {
    float z = 1.0f - 2.0f * u1;
    float s = sqrt(fmax(0.0f, 1.0f - z * z));
    float2 turn = s * Sampling_turn(u2);
    return (float3)(turn.x, turn.y, z);
}

/* A ray along dir through a uniform point of the disk of the bounding
 * sphere (centre xyz, radius w) facing it, starting outside the sphere. */
inline float3 PhotonEmit_disk_origin(float4 sphere, float3 dir, float u1, float u2) {
    float3 t, b;
    Sampling_frame(dir, &t, &b);
    float2 d = Sampling_disk(u1, u2) * sphere.w;
    return sphere.xyz - 1.01f * sphere.w * dir + d.x * t + d.y * b;
}

/* The bits of x at even places, gathered (a Morton code's x). */
inline uint PhotonEmit_compact(uint x) {
    x &= 0x55555555u;
    x = (x | (x >> 1)) & 0x33333333u;
    x = (x | (x >> 2)) & 0x0f0f0f0fu;
    x = (x | (x >> 4)) & 0x00ff00ffu;
    x = (x | (x >> 8)) & 0x0000ffffu;
    return x;
}

/* A direction sample of photon j of `count`: t = (j + u) / count, uniform
 * over [0, 1) across the photons, picks a cell of a g x g square in Morton
 * order (g the largest power of two with g^2 <= count, at most 2048), and
 * (v1, v2) a point in it. Every point of the square is as likely as
 * before, the photons stratified along the curve, and photons next to each
 * other leave in directions next to each other, so the rays a work-group
 * traces first run through the same part of the kd-tree. */
inline float2 PhotonEmit_ordered(int j, int count, float u, float v1, float v2) {
    int g = 1 << min((31 - (int)clz(max(count, 1))) / 2, 11);
    float t = ((float)j + u) / (float)max(count, 1);
    uint cell = min((uint)(t * (float)(g * g)), (uint)(g * g - 1));
    float2 c = (float2)((float)PhotonEmit_compact(cell), (float)PhotonEmit_compact(cell >> 1));
    return fmin((c + (float2)(v1, v2)) / (float)g, (float2)(0x1.fffffep-1f));
}

/* Emissive triangles: the one picked by u0 on the power CDF, a uniform
 * point and face, and the power of a photon from it out of `count`. */
inline PhotonRay PhotonEmit_mesh(const Emitters *em, int count, float u0, Rng *rng) {
    PhotonRay r;
    r.power = (float3)(0.0f);
    r.org = r.dir = (float3)(0.0f, 0.0f, 1.0f);
    int lo = 0, hi = em->count - 1;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (em->cdf[mid] <= u0) lo = mid + 1; else hi = mid;
    }
    float pick = em->cdf[lo] - (lo > 0 ? em->cdf[lo - 1] : 0.0f);
    int tri = em->tris[lo];
    float3 v0 = em->verts[3 * tri].xyz, v1 = em->verts[3 * tri + 1].xyz, v2 = em->verts[3 * tri + 2].xyz;
    float3 cr = cross(v1 - v0, v2 - v0);
    float len_cr = length(cr);
    if (!(pick > 0.0f && len_cr > 0.0f)) return r;
    /* numbers drawn into locals first, here and below: a call's arguments
     * are evaluated in no set order, and the stream must not depend on it */
    float b1 = Rng_next(rng), b2 = Rng_next(rng);
    float2 bc = Sampling_triangle(b1, b2);
    float3 n = cr / len_cr;
    if (Rng_next(rng) < 0.5f) n = -n;
    float eps = Ray_offset(fmax(fmax(Ray_magnitude(v0), Ray_magnitude(v1)), Ray_magnitude(v2)));
    r.org = v0 + bc.x * (v1 - v0) + bc.y * (v2 - v0) + eps * n;
    float d1 = Rng_next(rng), d2 = Rng_next(rng);
    r.dir = Sampling_cosine(n, d1, d2);
    float3 le = em->materials[em->tri_material[tri]].emission.xyz;
    r.power = le * (2.0f * PI_F * 0.5f * len_cr / (pick * (float)count));
    return r;
}

/* Photon j of emitter e; sphere is the scene's bounding sphere. */
inline PhotonRay PhotonEmit_photon(const PhotonEmitter *e, const __global Light *lights, const Emitters *em,
                            float4 sphere, int j, Rng *rng) {
    PhotonRay r;
    r.power = e->power.xyz;
    float u1 = Rng_next(rng), u2 = Rng_next(rng);
    if (e->light == PHOTON_EMITTER_WORLD) {
        r.dir = PhotonEmit_sphere(u1, u2);
        float o1 = Rng_next(rng), o2 = Rng_next(rng);
        r.org = PhotonEmit_disk_origin(sphere, r.dir, o1, o2);
        return r;
    }
    Light l = lights[e->light];
    if (l.kind == LIGHT_MESH) {
        /* stratified over the CDF, so the triangles get their share */
        return PhotonEmit_mesh(em, e->count, ((float)j + u1) / (float)e->count, rng);
    }
    if (l.kind == LIGHT_SUN) {
        float3 axis = l.direction.xyz;
        r.dir = l.cos_half < 1.0f ? Sampling_cone(axis, l.cos_half, u1, u2) : axis;
        float o1 = Rng_next(rng), o2 = Rng_next(rng);
        r.org = PhotonEmit_disk_origin(sphere, axis, o1, o2);
        return r;
    }
    if (l.kind == LIGHT_AREA) {
        float2 q = l.shape == AREA_ELLIPSE ? 0.5f * Sampling_disk(u1, u2) : (float2)(u1 - 0.5f, u2 - 0.5f);
        r.org = l.position.xyz + q.x * l.axis_u.xyz + q.y * l.axis_v.xyz;
        float d0 = Rng_next(rng), d1 = Rng_next(rng), d2 = Rng_next(rng);
        float2 d = PhotonEmit_ordered(j, e->count, d0, d1, d2);
        r.dir = Sampling_cosine(l.direction.xyz, d.x, d.y);
        return r;
    }
    r.org = l.position.xyz;
    float2 d = PhotonEmit_ordered(j, e->count, u1, u2, Rng_next(rng));
    if (l.kind == LIGHT_SPOT) {
        r.dir = Sampling_cone(l.direction.xyz, l.cos_half, d.x, d.y);
        r.power *= Light_spot_attenuation(&l, r.dir);
    } else {
        r.dir = PhotonEmit_sphere(d.x, d.y);
    }
    return r;
}

#endif
