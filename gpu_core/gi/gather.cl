/* Final gathering [WZPB09]: from every irradiance sample point, a
 * stratified set of cosine-distributed rays, followed through mirrors and
 * glass to their first diffuse hit y, where the radiance arriving is
 * albedo(y) / pi x E(y), E from the illumination cut (cut_lookup.h; its
 * nodes carry the caustic map's light too, gi/cut.py with_caustics).
 * Emitters and the world are not counted here: direct light is traced
 * separately, and light reaching the point from them through mirrors and
 * glass comes from the caustic map.
 *
 * One work-group of GATHER_GROUP work-items per sample point: its rays are
 * spread over the group and reduced in local memory to the sample's
 * irradiance (with cosine sampling, the mean of albedo(y) E(y)), the
 * harmonic mean distance of its hits, and its hit count. */
#include "device/rng.h"
#include "device/sampling.h"
#include "shading/surface.h"
#include "gi/cut_lookup.h"

/* Ray r of sample s (at p, normal n): the radiance arriving along it (times
 * pi: albedo(y) E(y)), and the distance of its first hit (< 0 when it
 * reached no diffuse surface). The rays split the unit square into
 * strata x strata cells, one jittered point each. */
inline float3 Gather_ray(const SceneView *sc, const Cut *cut, int max_specular, float3 p, float3 n, int s, int r,
                         int strata, uint seed, float *distance) {
    float3 none = (float3)(0.0f);
    *distance = -1.0f;
    Rng rng = Rng_make((uint)s, (uint)r, seed);
    float u1 = ((float)(r % strata) + Rng_next(&rng)) / (float)strata;
    float u2 = ((float)(r / strata) + Rng_next(&rng)) / (float)strata;
    float3 dir = Sampling_cosine(n, u1, u2);
    float3 org = p + Ray_offset(Ray_magnitude(p)) * n;
    float3 throughput = (float3)(1.0f);
    float first_t = -1.0f;
    for (int bounce = 0; bounce <= max_specular; ++bounce) {
        Hit hit;
        if (!KdTree_intersect(&sc->tree, org, dir, 0.0f, RAY_FAR, &hit)) return none;
        if (bounce == 0) first_t = hit.t;
        SurfacePoint sp = Surface_at(sc, dir, &hit);
        Material m = sc->materials[sp.material];
        float3 base = Surface_base(sc, &m, sp.uv);
        /* a diffuse lobe ends the ray; on a purely specular surface it goes on */
        float diffuse = Surface_diffuse_weight(&m);
        if (diffuse > 0.0f) {
            *distance = first_t;
            float3 albedo = throughput * base * diffuse * m.base_color.w;
            float3 e = CutLookup_irradiance(cut, sp.p, sp.ns);
            e = (float3)(isfinite(e.x) ? e.x : 0.0f, isfinite(e.y) ? e.y : 0.0f, isfinite(e.z) ? e.z : 0.0f);
            return albedo * fmax(e, none);
        }
        bool refracted;
        int lobe = Bsdf_pick(&m, Rng_next(&rng));
        float u = lobe == BSDF_GLASS ? Rng_next(&rng) : 0.0f;
        throughput *= Surface_specular(&sp, &m, lobe, base, u, &dir, &org, &refracted);
    }
    return none;
}

/* Work-group g gathers sample first + g. Outputs per sample: irradiance
 * (rgb), harmonic mean hit distance (INFINITY when no ray hit), hits. */
__kernel void Gather_samples(SCENE_PARAMS, CUT_PARAMS, const __global float4 *sample_pos, const __global float4 *sample_nrm,
                             const int first, const int sample_count, const int strata, const int max_specular,
                             const uint seed, __global float4 *out_irradiance, __global float *out_distance,
                             __global int *out_hits) {
    __local float4 sum_s[GATHER_GROUP];
    __local int hits_s[GATHER_GROUP];
    int s = first + get_group_id(0), lid = get_local_id(0);
    int rays = strata * strata;
    float3 sum = (float3)(0.0f);
    float inv_distance = 0.0f;
    int hits = 0;
    if (s < sample_count) {
        SceneView sc = SCENE_MAKE();
        Cut cut = CUT_MAKE();
        float3 p = sample_pos[s].xyz, n = sample_nrm[s].xyz;
        for (int r = lid; r < rays; r += GATHER_GROUP) {
            float t;
            sum += Gather_ray(&sc, &cut, max_specular, p, n, s, r, strata, seed, &t);
            if (t >= 0.0f) {
                inv_distance += 1.0f / fmax(t, 1e-30f);
                hits++;
            }
        }
    }
    sum_s[lid] = (float4)(sum, inv_distance);
    hits_s[lid] = hits;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int step = GATHER_GROUP / 2; step > 0; step /= 2) {
        if (lid < step) {
            sum_s[lid] += sum_s[lid + step];
            hits_s[lid] += hits_s[lid + step];
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0 && s < sample_count) {
        float4 total = sum_s[0];
        out_irradiance[s] = (float4)(total.xyz / (float)rays, 0.0f);
        out_distance[s] = hits_s[0] > 0 ? (float)hits_s[0] / total.w : INFINITY;
        out_hits[s] = hits_s[0];
    }
}
