/* Surface scattering: lobe choice, mirror reflection and dielectric Fresnel. */
#ifndef GPUGI_BSDF_H
#define GPUGI_BSDF_H
#include "types.h"

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

/* Scatter d off smooth glass with normal n (any side): reflect with the
 * Fresnel probability, else refract. Writes whether it refracted. */
inline float3 Bsdf_glass(float3 d, float3 n, float ior, float u, bool *refracted) {
    float cos_i = -dot(d, n);
    float3 nn = n;
    float eta = 1.0f / fmax(ior, 1e-3f);
    if (cos_i < 0.0f) { /* leaving the object */
        cos_i = -cos_i;
        nn = -n;
        eta = 1.0f / eta;
    }
    float cos_t;
    float f = Bsdf_fresnel(cos_i, eta, &cos_t);
    if (u < f) {
        *refracted = false;
        return Bsdf_reflect(d, nn);
    }
    *refracted = true;
    return normalize(eta * d + (eta * cos_i - cos_t) * nn);
}

#endif
