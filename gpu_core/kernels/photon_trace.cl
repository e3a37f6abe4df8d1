/* Photon tracing through the triangle kd-tree, one work item per emitted
 * photon. Scattering follows render.cl: stochastic alpha, then one lobe
 * by the Principled weights (mirror, smooth glass with Fresnel, Lambert);
 * Russian roulette by albedo keeps photon powers even; a bounce limit ends
 * long paths. Three passes use this kernel:
 *   global:  a photon is stored at every diffuse hit but those of paths
 *            light -> specular+ -> diffuse, which the caustic map holds;
 *   caustic: only paths light -> specular+ -> diffuse are followed, and the
 *            photon is stored at that diffuse hit;
 *   all:     a photon is stored at every diffuse hit (the global map of a
 *            scene whose caustic map is not traced).
 * Stored photons go to slots taken from an atomic counter; those past the
 * capacity are counted but not written, so the host can retry larger. */
#include "types.h"
#include "rng.h"
#include "sampling.h"
#include "ray.h"
#include "lights.h"
#include "bsdf.h"
#include "texture.h"
#include "kdtree_traverse.h"
#include "surface.h"
#include "photon_emit.h"

#define PHOTON_PASS_GLOBAL 0
#define PHOTON_PASS_CAUSTIC 1
#define PHOTON_PASS_ALL 2
#define PHOTON_MAX_PASSTHROUGH 64

/* Russian roulette by albedo: survive with probability max(albedo), the
 * survivor's power scaled by albedo / that probability. */
inline bool Photon_roulette(float3 albedo, float3 *power, Rng *rng) {
    float q = fmin(fmax(fmax(albedo.x, albedo.y), albedo.z), 1.0f);
    if (!(q > 0.0f) || Rng_next(rng) >= q) return false;
    *power *= albedo / q;
    return true;
}

/* Emitter of photon i: the last one whose first photon is <= i. */
inline int Photon_emitter(const __global PhotonEmitter *emitters, int n_emitters, int i) {
    int lo = 0, hi = n_emitters - 1;
    while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        if (emitters[mid].first <= i) lo = mid; else hi = mid - 1;
    }
    return lo;
}

/* Store a photon: position (w = its slot, as the point tree's index),
 * incident direction pointing back along the path, power, normal. */
inline void Photon_store(float3 p, float3 incident, float3 power, float3 n, volatile __global int *counter,
                         int capacity, __global float4 *out_pos, __global float4 *out_dir,
                         __global float4 *out_power, __global float4 *out_normal) {
    int slot = atomic_inc(counter);
    if (slot >= capacity) return;
    out_pos[slot] = (float4)(p, as_float(slot));
    out_dir[slot] = (float4)(incident, 0.0f);
    out_power[slot] = (float4)(power, 0.0f);
    out_normal[slot] = (float4)(n, 0.0f);
}

/* One photon path per work item. path_out[i] = (emitted power rgb, surface
 * hits of the path), for the host's statistics. */
__kernel void Photon_trace(KDTREE_PARAMS, const __global float4 *tri_normals,
                           const __global float2 *tri_uvs, const __global int *tri_material,
                           const __global Material *materials, const __global Light *lights,
                           const __global int *emit_tris, const __global float *emit_cdf,
                           const int emit_count, const __global float4 *tex_atlas,
                           const __global TextureInfo *tex_infos,
                           const __global PhotonEmitter *emitters, const int n_emitters,
                           const float4 sphere, const int n_photons, const uint seed,
                           const int pass, const int max_bounces, volatile __global int *counter,
                           const int capacity, __global float4 *out_pos, __global float4 *out_dir,
                           __global float4 *out_power, __global float4 *out_normal,
                           __global float4 *path_out) {
    int i = get_global_id(0);
    if (i >= n_photons) return;
    KdTree tree = KDTREE_MAKE();
    Emitters em = {emit_tris, emit_cdf, emit_count, kd_verts, tri_material, materials};
    Rng rng = Rng_make((uint)i, pass == PHOTON_PASS_CAUSTIC ? 1u : 0u, seed); /* one stream per map */
    PhotonEmitter e = emitters[Photon_emitter(emitters, n_emitters, i)];
    PhotonRay ray = PhotonEmit(&e, lights, &em, sphere, i - e.first, &rng);
    float3 org = ray.org, dir = ray.dir, power = ray.power;
    path_out[i] = (float4)(power, 0.0f);
    if (!(power.x > 0.0f || power.y > 0.0f || power.z > 0.0f)) return;

    int hits = 0, bounces = 0, passes = 0;
    bool caustic = false; /* the path so far is light -> specular+ */
    while (true) {
        Hit hit;
        if (!KdTree_intersect(&tree, org, dir, 0.0f, RAY_FAR, &hit)) break;
        hits++;
        SurfacePoint sp = Surface_at(&tree, tri_normals, tri_uvs, tri_material, dir, &hit);
        Material m = materials[sp.material];
        float3 base = Surface_base(&m, tex_atlas, tex_infos, sp.uv);
        /* stochastic alpha: pass straight through */
        if (m.base_color.w < 1.0f && Rng_next(&rng) >= m.base_color.w && passes < PHOTON_MAX_PASSTHROUGH) {
            passes++;
            org = sp.p - sp.eps * sp.ng;
            continue;
        }
        int lobe = Bsdf_pick(&m, Rng_next(&rng));
        if (lobe == BSDF_DIFFUSE) {
            if (pass == PHOTON_PASS_ALL || (pass == PHOTON_PASS_GLOBAL) != caustic)
                Photon_store(sp.p, -dir, power, sp.ns, counter, capacity, out_pos, out_dir, out_power, out_normal);
            if (pass == PHOTON_PASS_CAUSTIC || bounces >= max_bounces) break;
            if (!Photon_roulette(base, &power, &rng)) break;
            dir = Sampling_cosine(sp.ns, Rng_next(&rng), Rng_next(&rng));
            if (dot(dir, sp.ng) <= 0.0f) break;
            org = sp.p + sp.eps * sp.ng;
            caustic = false;
            bounces++;
            continue;
        }
        if (bounces >= max_bounces) break;
        bool refracted;
        float u = lobe == BSDF_GLASS ? Rng_next(&rng) : 0.0f;
        float3 tint = Surface_specular(&sp, &m, lobe, base, u, &dir, &org, &refracted);
        /* a glass reflection keeps all the power: no roulette */
        if ((lobe == BSDF_MIRROR || refracted) && !Photon_roulette(tint, &power, &rng)) break;
        /* specular straight from the light starts a caustic path */
        caustic = bounces == 0 || caustic;
        bounces++;
    }
    path_out[i].w = (float)hits;
}
