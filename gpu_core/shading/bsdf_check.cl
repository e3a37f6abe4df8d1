/* The BSDF as tests probe it (tests/shading): directions sampled from one
 * material seen from one direction, and the BSDF evaluated on given
 * directions, all in the frame of a surface whose geometric normal is +z. */
#include "device/launch.h"
#include "device/rng.h"
#include "shading/bsdf.h"

/* The BSDF of material m (base colour its own) seen from wo (wo.z > 0) on
 * a surface of geometric normal +z, smooth shading normal ns (ns.z > 0)
 * and tangent +x. */
inline Bsdf BsdfCheck_make(const __global Material *m, float4 wo, float4 ns, int entering, int sample) {
    Material mat = *m;
    float3 n = normalize(ns.xyz);
    return Bsdf_make(&mat, mat.base_color.xyz, normalize(wo.xyz), n, n, (float3)(0.0f, 0.0f, 1.0f),
                     (float3)(1.0f, 0.0f, 0.0f), entering != 0, sample);
}

/* Sample of f with the numbers u: direction (w = label) to out_dir[i],
 * weight (w = pdf) to out_weight[i]. */
inline void BsdfCheck_store(const Bsdf *f, float4 u, int i, __global float4 *out_dir, __global float4 *out_weight) {
    float3 wi = (float3)(0.0f), weight = (float3)(0.0f);
    float pdf = 0.0f;
    int label = Bsdf_sample(f, u.x, u.y, u.z, u.w, &wi, &weight, &pdf);
    out_dir[i] = (float4)(Bsdf_to_world(f, wi), (float)label);
    out_weight[i] = (float4)(weight, pdf);
}

/* One sample per work item from the random stream of seed. */
__kernel void BsdfCheck_sample(const __global Material *m, const float4 wo, const float4 ns, const int entering,
                               const int sample, const uint seed, const int n, __global float4 *out_dir,
                               __global float4 *out_weight) {
    int i = Launch_global_id();
    if (i >= n) return;
    Bsdf f = BsdfCheck_make(m, wo, ns, entering, sample);
    Rng rng = Rng_make((uint)i, 7u, seed);
    float u0 = Rng_next(&rng), u1 = Rng_next(&rng), u2 = Rng_next(&rng), u3 = Rng_next(&rng);
    BsdfCheck_store(&f, (float4)(u0, u1, u2, u3), i, out_dir, out_weight);
}

/* One sample per work item from the given numbers u[i] (lobe, u1, u2, u3). */
__kernel void BsdfCheck_sample_at(const __global Material *m, const float4 wo, const float4 ns, const int entering,
                                  const int sample, const __global float4 *u, const int n,
                                  __global float4 *out_dir, __global float4 *out_weight) {
    int i = Launch_global_id();
    if (i >= n) return;
    Bsdf f = BsdfCheck_make(m, wo, ns, entering, sample);
    BsdfCheck_store(&f, u[i], i, out_dir, out_weight);
}

/* The BSDF on direction wi[i]: diffuse part of f cos, glossy part (w =
 * pdf). */
__kernel void BsdfCheck_eval(const __global Material *m, const float4 wo, const float4 ns, const int entering,
                             const int sample, const __global float4 *wi, const int n, __global float4 *out_diffuse,
                             __global float4 *out_glossy) {
    int i = Launch_global_id();
    if (i >= n) return;
    Bsdf f = BsdfCheck_make(m, wo, ns, entering, sample);
    float3 d;
    float pdf;
    float3 g = Bsdf_eval(&f, Bsdf_to_local(&f, wi[i].xyz), &d, &pdf);
    out_diffuse[i] = (float4)(d, 0.0f);
    out_glossy[i] = (float4)(g, pdf);
}
