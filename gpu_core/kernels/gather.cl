/* Final-gather rays [WZPB09]: from every irradiance sample point, a
 * stratified set of cosine-distributed rays, followed through mirrors and
 * glass to their first diffuse hit, which is written out for the
 * illumination-cut lookup on the host (gpu_core/gather.py). Emitters and the
 * world are not counted here: direct light is traced separately, and light
 * reaching the point from them through mirrors and glass comes from the
 * caustic map. */
#include "types.h"
#include "rng.h"
#include "sampling.h"
#include "bsdf.h"
#include "surface.h"

#define GATHER_MAX_SPECULAR 8

/* One work item per (sample, ray): ray r of sample s is g = s * rays + r; the
 * rays of a sample split the unit square into strata x strata cells, one
 * jittered point each (rays = strata^2). Outputs per ray: hit position (w =
 * distance of the first hit, or -1 where no diffuse surface was reached),
 * shading normal facing the ray, and the hit's diffuse albedo (diffuse weight
 * x base colour) times the colour of the mirrors and glass on the way. */
__kernel void Gather_rays(KDTREE_PARAMS, SURFACE_PARAMS, const __global float4 *sample_pos,
                          const __global float4 *sample_nrm, const int sample_count,
                          const int strata, const uint seed, __global float4 *out_pos,
                          __global float4 *out_nrm, __global float4 *out_albedo) {
    int g = get_global_id(0);
    int rays = strata * strata;
    if (g >= sample_count * rays) return;
    int s = g / rays, r = g % rays;
    KdTree tree = KDTREE_MAKE();
    out_pos[g] = (float4)(0.0f, 0.0f, 0.0f, -1.0f);
    out_nrm[g] = (float4)(0.0f);
    out_albedo[g] = (float4)(0.0f);
    float3 p = sample_pos[s].xyz, n = sample_nrm[s].xyz;
    Rng rng = Rng_make((uint)s, (uint)r, seed);
    float u1 = ((float)(r % strata) + Rng_next(&rng)) / (float)strata;
    float u2 = ((float)(r / strata) + Rng_next(&rng)) / (float)strata;
    float3 dir = Sampling_cosine(n, u1, u2);
    float3 org = p + Ray_offset(Ray_magnitude(p)) * n;
    float3 throughput = (float3)(1.0f);
    float first_t = -1.0f;
    for (int bounce = 0; bounce <= GATHER_MAX_SPECULAR; ++bounce) {
        Hit hit;
        if (!KdTree_intersect(&tree, org, dir, 0.0f, RAY_FAR, &hit)) return;
        if (bounce == 0) first_t = hit.t;
        SurfacePoint sp = Surface_at(&tree, tri_normals, tri_uvs, tri_material, dir, &hit);
        Material m = materials[sp.material];
        float3 base = Surface_base(&m, tex_atlas, tex_infos, sp.uv);
        /* a diffuse lobe ends the ray; on a purely specular surface it goes on */
        float diffuse = Surface_diffuse_weight(&m);
        if (diffuse > 0.0f) {
            out_pos[g] = (float4)(sp.p, first_t);
            out_nrm[g] = (float4)(sp.ns, 0.0f);
            out_albedo[g] = (float4)(throughput * base * diffuse * m.base_color.w, 0.0f);
            return;
        }
        bool refracted;
        int lobe = Bsdf_pick(&m, Rng_next(&rng));
        float u = lobe == BSDF_GLASS ? Rng_next(&rng) : 0.0f;
        throughput *= Surface_specular(&sp, &m, lobe, base, u, &dir, &org, &refracted);
    }
}
