/* Photon tracing through the triangle kd-tree, one work item per emitted
 * photon. Scattering follows image.cl: stochastic alpha, then a direction
 * sampled from the surface's BSDF (shading/bsdf.h: diffuse, glossy and
 * singular lobes); Russian roulette by the sample's weight keeps photon
 * powers even; a limit on scattering events and one on specular bounces
 * end long paths. A bounce is "specular" when it is singular or glossy
 * below CAUSTIC_ROUGHNESS (LuxCore's PhotonGI draws the same line): light
 * it focuses is a caustic. Three passes (PHOTON_PASS_*) use this kernel:
 *   global:  a photon is stored at every hit on a surface with a diffuse
 *            lobe but those of paths light -> specular+ -> diffuse, which
 *            the caustic map holds;
 *   caustic: only paths light -> specular+ -> diffuse are followed, and the
 *            photon is stored at that diffuse hit;
 *   all:     a photon is stored at every diffuse hit (the global map of a
 *            scene whose caustic map is not traced).
 * Stored photons go to slots taken from an atomic counter; those past the
 * capacity are counted but not written, so the host can retry larger (it
 * sizes the buffers from a first launch over every `step`-th photon). Each
 * also gets a key, photon index x stride + its stores so far, by which the
 * host puts them in an order that does not depend on the scheduling
 * (Photon_reorder): the same scene gives the same photon maps. The caustic
 * pass traces only the photons whose first ray meets one of the n_aim
 * boxes (every photon when n_aim is negative), which hold every surface
 * that can bounce light specularly (photons/aim.py): any other photon
 * would end its caustic path at its first hit with nothing stored, so the
 * map is the same; counter[1] counts the photons skipped. A photon's
 * power carries the index of its emitter in w, so that a change of light
 * power alone reweights the maps instead (photon_reweight.cl). */
#include "device/launch.h"
#include "shading/surface.h"
#include "photons/photon_emit.h"

#define PHOTON_MAX_PASSTHROUGH 64

/* Russian roulette by a scattering weight: survive with probability
 * max(weight) (at most 1), the survivor's power scaled by weight / that
 * probability. */
inline bool Photon_roulette(float3 weight, float3 *power, Rng *rng) {
    float q = fmin(fmax(fmax(weight.x, weight.y), weight.z), 1.0f);
    if (!(q > 0.0f) || Rng_next(rng) >= q) return false;
    *power *= weight / q;
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

/* Store a photon: position, incident direction pointing back along the
 * path, power with its emitter's index, normal, and its key. */
inline void Photon_store(float3 p, float3 incident, float3 power, int emitter, float3 n, uint key,
                         volatile __global int *counter,
                         int capacity, __global float4 *out_pos, __global float4 *out_dir,
                         __global float4 *out_power, __global float4 *out_normal, __global uint *out_key) {
    int slot = atomic_inc(counter);
    if (slot >= capacity) return;
    out_key[slot] = key;
    out_pos[slot] = (float4)(p, 0.0f);
    out_dir[slot] = (float4)(incident, 0.0f);
    out_power[slot] = (float4)(power, (float)emitter);
    out_normal[slot] = (float4)(n, 0.0f);
}

/* Whether the ray org + t dir, t >= 0, meets one of the n boxes (low and
 * high corners in turn). A plane the ray runs in gives NaN distances,
 * which fmin and fmax pass over: that axis does not bound it. */
inline bool Photon_aimed(const __global float4 *aim, int n, float3 org, float3 dir) {
    float3 inv = 1.0f / dir;
    for (int b = 0; b < n; ++b) {
        float3 t0 = (aim[2 * b].xyz - org) * inv, t1 = (aim[2 * b + 1].xyz - org) * inv;
        float3 lo = fmin(t0, t1), hi = fmax(t0, t1);
        if (fmax(fmax(lo.x, lo.y), fmax(lo.z, 0.0f)) <= fmin(fmin(hi.x, hi.y), hi.z)) return true;
    }
    return false;
}

/* One photon path per work item: photon i = step x the work item's index.
 * path_out[i] = (emitted power rgb, surface hits of the path), for the
 * host's statistics. */
__kernel void Photon_trace(SCENE_PARAMS, const __global PhotonEmitter *emitters, const int n_emitters,
                           const float4 sphere, const __global float4 *aim, const int n_aim, const int n_photons,
                           const uint seed, const int pass,
                           const int max_bounces, const int max_specular, volatile __global int *counter,
                           const int capacity, __global float4 *out_pos, __global float4 *out_dir,
                           __global float4 *out_power, __global float4 *out_normal, __global uint *out_key,
                           const uint key_stride, __global float4 *path_out, const int step) {
    if (Launch_global_id() >= (n_photons + step - 1) / step) return;
    int i = Launch_global_id() * step;
    SceneView sc = SCENE_MAKE();
    Rng rng = Rng_make((uint)i, pass == PHOTON_PASS_CAUSTIC ? 1u : 0u, seed); /* one stream per map */
    int emitter = Photon_emitter(emitters, n_emitters, i);
    PhotonEmitter e = emitters[emitter];
    PhotonRay ray = PhotonEmit_photon(&e, sc.lights, &sc.em, sphere, i - e.first, &rng);
    float3 org = ray.org, dir = ray.dir, power = ray.power;
    path_out[i] = (float4)(power, 0.0f);
    if (!(power.x > 0.0f || power.y > 0.0f || power.z > 0.0f)) return;
    if (pass == PHOTON_PASS_CAUSTIC && n_aim >= 0 && !Photon_aimed(aim, n_aim, org, dir)) {
        atomic_inc(&counter[1]);
        return;
    }

    int hits = 0, bounces = 0, specular = 0, passes = 0;
    uint stores = 0;
    bool caustic = false; /* the path so far is light -> specular+ */
    while (true) {
        Hit hit;
        if (!KdTree_intersect(&sc.tree, org, dir, 0.0f, RAY_FAR, &hit)) break;
        hits++;
        SurfacePoint sp = Surface_at(&sc, dir, &hit);
        Material m = Surface_material(&sc, sp.tri, sp.uv, SURFACE_MIX_U(&rng));
        float3 base = Surface_textured(&sc, &m, &sp);
        /* stochastic alpha: pass straight through */
        if (m.base_color.w < 1.0f && Rng_next(&rng) >= m.base_color.w && passes < PHOTON_MAX_PASSTHROUGH) {
            passes++;
            power *= m.mix_scale * Surface_pass_tint(&m);
            org = sp.p - sp.eps * sp.ng;
            continue;
        }
        Bsdf f = Surface_bsdf(&sp, &m, base, dir, BSDF_SAMPLE_ALL);
        bool diffuse = f.diffuse.x > 0.0f || f.diffuse.y > 0.0f || f.diffuse.z > 0.0f;
        if (diffuse && (pass == PHOTON_PASS_ALL || (pass == PHOTON_PASS_GLOBAL) != caustic)) {
            Photon_store(sp.p, -dir, power, emitter, sp.ns, (uint)i * key_stride + stores++, counter, capacity,
                         out_pos, out_dir, out_power, out_normal, out_key);
            if (pass == PHOTON_PASS_CAUSTIC) break;
        }
        if (bounces >= max_bounces) break;
        float3 wi, weight;
        float pdf;
        /* drawn in a fixed order (a call's arguments are evaluated in none) */
        float u_lobe = Rng_next(&rng), u1 = Rng_next(&rng), u2 = Rng_next(&rng), u3 = Rng_next(&rng);
        int label = Bsdf_sample(&f, u_lobe, u1, u2, u3, &wi, &weight, &pdf);
        if (label == 0) break;
        bool specular_bounce = (label & BSDF_LABEL_SINGULAR) || ((label & BSDF_LABEL_GLOSSY) && f.rough < CAUSTIC_ROUGHNESS);
        /* the caustic pass follows specular chains only */
        if (pass == PHOTON_PASS_CAUSTIC && !specular_bounce) break;
        if (specular_bounce && specular >= max_specular) break;
        if (!Photon_roulette(weight, &power, &rng)) break;
        dir = Bsdf_to_world(&f, wi);
        org = Surface_leave(&sp, dir);
        /* specular straight from the light starts a caustic path */
        caustic = specular_bounce && (bounces == 0 || caustic);
        bounces++;
        specular += specular_bounce ? 1 : 0;
    }
    path_out[i].w = (float)hits;
}

/* The stored photons in key order (order[j]: the slot of the j-th smallest
 * key), each position's w its new index, as the point tree takes them. */
__kernel void Photon_reorder(const __global int *order, const int n, const __global float4 *pos,
                             const __global float4 *dir, const __global float4 *power, const __global float4 *normal,
                             __global float4 *out_pos, __global float4 *out_dir, __global float4 *out_power,
                             __global float4 *out_normal) {
    int j = Launch_global_id();
    if (j >= n) return;
    int o = order[j];
    out_pos[j] = (float4)(pos[o].xyz, as_float(j));
    out_dir[j] = dir[o];
    out_power[j] = power[o];
    out_normal[j] = normal[o];
}
