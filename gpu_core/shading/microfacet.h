/* GGX microfacets as Cycles has them: the distribution with alpha =
 * roughness^2, Smith's height-correlated masking-shadowing, sampling of
 * the visible normals (Heitz 2018), the dielectric Fresnel and its remap
 * between a tinted F0 and 1, Cycles' F82-tint conductor Fresnel, and the
 * albedo tables of Multiscatter GGX (shading/microfacet_tables.py).
 * Directions are in the local frame of the shading normal (z up). */
#ifndef GPUGI_MICROFACET_H
#define GPUGI_MICROFACET_H
#include "device/sampling.h"
#include "shading/microfacet_tables.h"

/* At or below this alpha^2 a lobe is a perfect mirror or smooth glass. */
#define MICROFACET_SINGULAR_ALPHA2 2e-10f

inline float Microfacet_D(float alpha2, float cos_h) {
    float c2 = fmin(cos_h * cos_h, 1.0f);
    float d = (1.0f - c2) + alpha2 * c2;
    return alpha2 / (PI_F * fmax(d * d, 1e-30f));
}

inline float Microfacet_lambda(float alpha2, float cos_n) {
    float c2 = fmax(cos_n * cos_n, 1e-30f);
    return 0.5f * (sqrt(1.0f + alpha2 * fmax(1.0f / c2 - 1.0f, 0.0f)) - 1.0f);
}

/* Anisotropic GGX, alpha ax along local x and ay along y: the
 * distribution and Smith's Lambda (equal to the above where ax = ay). */
inline float Microfacet_D_aniso(float ax, float ay, float3 h) {
    float3 s = (float3)(h.x / ax, h.y / ay, h.z);
    float l = dot(s, s);
    return 1.0f / (PI_F * ax * ay * fmax(l * l, 1e-30f));
}

inline float Microfacet_lambda_aniso(float ax, float ay, float3 v) {
    float z2 = fmax(v.z * v.z, 1e-30f);
    return 0.5f * (sqrt(1.0f + (ax * ax * v.x * v.x + ay * ay * v.y * v.y) / z2) - 1.0f);
}

/* A visible normal for the view wo (wo.z > 0), u in [0, 1)^2, of the
 * distribution with alpha ax along x and ay along y. */
inline float3 Microfacet_sample_vndf(float3 wo, float ax, float ay, float u1, float u2) {
    float3 vh = normalize((float3)(ax * wo.x, ay * wo.y, wo.z));
    float lensq = vh.x * vh.x + vh.y * vh.y;
    float3 t1 = lensq > 0.0f ? (float3)(-vh.y, vh.x, 0.0f) * rsqrt(lensq) : (float3)(1.0f, 0.0f, 0.0f);
    float3 t2 = cross(vh, t1);
    float2 disk = Sampling_disk(u1, u2);
    float a = disk.x, b = disk.y;
    float s = 0.5f * (1.0f + vh.z);
    b = (1.0f - s) * sqrt(fmax(0.0f, 1.0f - a * a)) + s * b;
    float3 nh = a * t1 + b * t2 + sqrt(fmax(0.0f, 1.0f - a * a - b * b)) * vh;
    float3 ne = (float3)(ax * nh.x, ay * nh.y, fmax(nh.z, 0.0f));
    float len = length(ne);
    return len > 0.0f ? ne / len : (float3)(0.0f, 0.0f, 1.0f);
}

/* Fresnel reflectance of a dielectric, eta = n_transmitted / n_incident
 * (1 on total internal reflection), for |cos| to the microfacet normal. */
inline float Microfacet_fresnel_dielectric(float cos_i, float eta) {
    float c = fabs(cos_i);
    float g = eta * eta - 1.0f + c * c;
    if (g <= 0.0f) return 1.0f;
    g = sqrt(g);
    float a = (g - c) / (g + c);
    float b = (c * (g + c) - 1.0f) / (c * (g - c) + 1.0f);
    return 0.5f * a * a * (1.0f + b * b);
}

inline float Microfacet_f0(float eta) {
    float r = (eta - 1.0f) / (eta + 1.0f);
    return r * r;
}

/* Cycles' generalized Schlick with a negative exponent: the real
 * dielectric curve remapped from [F0(eta), 1] to [f0, 1]. */
inline float3 Microfacet_fresnel_remap(float3 f0, float cos_i, float eta) {
    float real0 = Microfacet_f0(eta);
    float s = clamp((Microfacet_fresnel_dielectric(cos_i, eta) - real0) / fmax(1.0f - real0, 1e-7f), 0.0f, 1.0f);
    return mix(f0, (float3)(1.0f), s);
}

/* Cycles' F82-tint conductor: Schlick from f0 minus b mu (1 - mu)^6. */
inline float3 Microfacet_fresnel_f82(float3 f0, float3 b, float cos_i) {
    float m = clamp(1.0f - cos_i, 0.0f, 1.0f);
    float m5 = (m * m) * (m * m) * m;
    return clamp(mix(f0, (float3)(1.0f), m5) - b * (cos_i * m5 * m), 0.0f, 1.0f);
}

/* Table lookups: grid points i / (N - 1), clamped at the ends. */
inline float Microfacet_lerp_index(float x, int n, int *i) {
    float f = clamp(x, 0.0f, 1.0f) * (float)(n - 1);
    *i = min((int)f, n - 2);
    return f - (float)*i;
}

/* A table t[x][y] of n x n points, read bilinearly. */
inline float Microfacet_lookup2(__constant float *t, int n, float x, float y) {
    int i, j;
    float fx = Microfacet_lerp_index(x, n, &i), fy = Microfacet_lerp_index(y, n, &j);
    __constant float *row0 = t + i * n, *row1 = row0 + n;
    return mix(mix(row0[j], row0[j + 1], fy), mix(row1[j], row1[j + 1], fy), fx);
}

/* A table t[x][y][z] of n x n x n points, read trilinearly. */
inline float Microfacet_lookup3(__constant float *t, int n, float x, float y, float z) {
    int i;
    float fx = Microfacet_lerp_index(x, n, &i);
    return mix(Microfacet_lookup2(t + i * n * n, n, y, z), Microfacet_lookup2(t + (i + 1) * n * n, n, y, z), fx);
}

/* E(rough, mu): single-scattering albedo with Fresnel 1. */
inline float Microfacet_E(float rough, float mu) {
    return fmax(Microfacet_lookup2(Microfacet_table_E, MICROFACET_E_SIZE, rough, mu), 1e-4f);
}

inline float Microfacet_E_avg(float rough) {
    int i;
    float f = Microfacet_lerp_index(rough, MICROFACET_E_SIZE, &i);
    return mix(Microfacet_table_E_avg[i], Microfacet_table_E_avg[i + 1], f);
}

/* The tables' coordinate of an index: z = sqrt(|eta - 1| / (eta + 1)). */
inline float Microfacet_index_z(float eta) {
    return sqrt(fabs((eta - 1.0f) / (eta + 1.0f)));
}

/* S(rough, mu, eta): the lobe's mean Fresnel remap over E. */
inline float Microfacet_S(float rough, float mu, float eta) {
    return Microfacet_lookup3(Microfacet_table_S, MICROFACET_S_SIZE, Microfacet_index_z(eta), mu, rough);
}

/* Kulla and Conty's multiple-scattering factor on a lobe of single-
 * scattering albedo e (hemispherical mean e_avg) and mean Fresnel f_ss:
 * 1 + F_ms (1 - e) / e, as Cycles' Multiscatter GGX applies it. */
inline float3 Microfacet_ms_factor(float e, float e_avg, float3 f_ss) {
    float3 f_ms = f_ss * e_avg / ((float3)(1.0f) - f_ss * (1.0f - e_avg));
    return (float3)(1.0f) + f_ms * ((1.0f - e) / e);
}

/* Multiscatter GGX on a reflection lobe. */
inline float3 Microfacet_multiscatter(float rough, float mu, float3 f_ss) {
    return Microfacet_ms_factor(Microfacet_E(rough, mu), Microfacet_E_avg(rough), f_ss);
}

/* Multiscatter GGX on glass seen from the side where eta = n_t / n_i: the
 * albedo tables of that side (shading/microfacet_tables.py, G), f_ss the
 * transmission tint (Cycles takes it as most of the glass's colour). */
inline float3 Microfacet_glass_multiscatter(float rough, float mu, float eta, float3 f_ss) {
    int side = eta < 1.0f ? 1 : 0;
    float z = Microfacet_index_z(side ? 1.0f / eta : eta);
    const int n = MICROFACET_G_SIZE;
    float e = fmax(Microfacet_lookup3(Microfacet_table_G + side * n * n * n, n, z, mu, rough), 1e-4f);
    float e_avg = Microfacet_lookup2(Microfacet_table_G_avg + side * n * n, n, z, rough);
    return Microfacet_ms_factor(e, e_avg, f_ss);
}

/* Reflection off the microfacets: f cos_i (Fresnel left out) and the
 * pdf of sampling wi by the visible normals; wo.z, wi.z > 0. */
inline float Microfacet_reflect_eval(float alpha2, float3 wo, float3 wi, float *pdf) {
    float3 h = normalize(wo + wi);
    float d = Microfacet_D(alpha2, h.z);
    float lo = Microfacet_lambda(alpha2, wo.z), li = Microfacet_lambda(alpha2, wi.z);
    float common = d / (4.0f * wo.z);
    *pdf = common / (1.0f + lo);
    return common / (1.0f + lo + li);
}

/* The same for the anisotropic distribution. */
inline float Microfacet_reflect_eval_aniso(float ax, float ay, float3 wo, float3 wi, float *pdf) {
    float3 h = normalize(wo + wi);
    float d = Microfacet_D_aniso(ax, ay, h);
    float lo = Microfacet_lambda_aniso(ax, ay, wo), li = Microfacet_lambda_aniso(ax, ay, wi);
    float common = d / (4.0f * wo.z);
    *pdf = common / (1.0f + lo);
    return common / (1.0f + lo + li);
}

/* Refraction through the microfacets (eta = n_t / n_i, wi.z < 0): f |cos_i|
 * (Fresnel left out), its pdf by the visible normals, and the microfacet
 * normal in *h (h.z >= 0). As Cycles evaluates it: every term takes the
 * cosines to h by their absolute values, so a pair of directions whose
 * half vector faces away from one of them (a refraction no microfacet
 * makes, which sampling never produces) still gets a value and a pdf.
 * False where the half vector is undefined. */
inline bool Microfacet_refract_eval(float alpha2, float eta, float3 wo, float3 wi, float *value, float *pdf,
                                    float3 *h_out) {
    float3 h = -(eta * wi + wo);
    float len = length(h);
    if (!(len > 0.0f)) return false;
    h /= len;
    if (h.z < 0.0f) h = -h;
    float c_o = dot(h, wo), c_i = dot(h, wi);
    float d = Microfacet_D(alpha2, h.z);
    float lo = Microfacet_lambda(alpha2, wo.z), li = Microfacet_lambda(alpha2, wi.z);
    float common = d / wo.z * (eta * eta * fabs(c_o * c_i)) / (len * len);
    *pdf = common / (1.0f + lo);
    *value = common / (1.0f + lo + li);
    *h_out = h;
    return true;
}

/* The refraction of wo by the microfacet normal h (cos_o = wo.h > 0, eta =
 * n_t / n_i); false on total internal reflection. */
inline bool Microfacet_refract(float3 wo, float3 h, float eta, float3 *wi) {
    float c = dot(wo, h);
    float g = 1.0f - (1.0f - c * c) / (eta * eta);
    if (g <= 0.0f) return false;
    *wi = normalize((c / eta - sqrt(g)) * h - wo / eta);
    return true;
}

#endif
