/* Surface scattering: lobe choice, mirror reflection and dielectric Fresnel. */
#ifndef GPUGI_BSDF_H
#define GPUGI_BSDF_H
#include "device/structs.h"

#define BSDF_DIFFUSE 0
#define BSDF_MIRROR 1
#define BSDF_GLASS 2

/* Pick one lobe with the Principled weights: metallic mirror, then glass by
 * transmission, else diffuse. The weights sum to one, so the pick needs no
 * reweighting. */
inline int Bsdf_pick(const Material *m, float u) {
    float w_mirror = clamp(m->metallic, 0.0f, 1.0f);
    float w_glass = (1.0f - w_mirror) * clamp(m->transmission, 0.0f, 1.0f);
    if (u < w_mirror) return BSDF_MIRROR;
    if (u < w_mirror + w_glass) return BSDF_GLASS;
    return BSDF_DIFFUSE;
}

inline float3 Bsdf_reflect(float3 d, float3 n) { return d - 2.0f * dot(d, n) * n; }

/* Perfect mirror about the shading normal n, or about the geometric normal
 * ng (facing d's origin) where n would reflect below the surface. */
inline float3 Bsdf_mirror(float3 d, float3 n, float3 ng) {
    float3 r = Bsdf_reflect(d, n);
    return dot(r, ng) > 0.0f ? r : Bsdf_reflect(d, ng);
}

/* Unpolarised Fresnel reflectance of a dielectric; cos_i > 0 on the incident
 * side, eta = n_incident / n_transmitted. Returns 1 on total internal
 * reflection and writes cos_t otherwise. */
inline float Bsdf_fresnel(float cos_i, float eta, float *cos_t) {
    float sin2_t = eta * eta * fmax(0.0f, 1.0f - cos_i * cos_i);
    if (sin2_t >= 1.0f) {
        *cos_t = 0.0f;
        return 1.0f;
    }
    float ct = sqrt(1.0f - sin2_t);
    *cos_t = ct;
    float rs = (eta * cos_i - ct) / (eta * cos_i + ct);
    float rp = (cos_i - eta * ct) / (cos_i + eta * ct);
    return 0.5f * (rs * rs + rp * rp);
}

/* Scatter d off smooth glass: reflect with the Fresnel probability, else
 * refract. `entering` (from the geometric normal) sets the side of the
 * index change; n is the shading normal on the incident side and ng the
 * geometric one, used instead where the smooth normal would send the ray to
 * the wrong side of the surface. Writes whether it refracted. */
inline float3 Bsdf_glass(float3 d, float3 n, float3 ng, bool entering, float ior, float u, bool *refracted) {
    float eta = entering ? 1.0f / ior : ior;
    if (dot(d, n) >= 0.0f) n = ng;
    float cos_i = -dot(d, n);
    float cos_t;
    float f = Bsdf_fresnel(cos_i, eta, &cos_t);
    *refracted = u >= f;
    if (!*refracted) return Bsdf_mirror(d, n, ng);
    float3 t = normalize(eta * d + (eta * cos_i - cos_t) * n);
    if (dot(t, ng) < 0.0f) return t;
    /* the smooth normal bent the ray back: refract by the geometric normal */
    cos_i = -dot(d, ng);
    f = Bsdf_fresnel(cos_i, eta, &cos_t);
    if (f >= 1.0f) {
        *refracted = false;
        return Bsdf_reflect(d, ng);
    }
    return normalize(eta * d + (eta * cos_i - cos_t) * ng);
}

#endif
