/* Final gathering [WZPB09]: from every irradiance sample point, a
 * stratified set of cosine-distributed rays; at each surface y with a
 * diffuse lobe the radiance arriving is albedo(y) / pi x E(y), E from the
 * illumination cut (cut_lookup.h; its nodes carry the caustic map's light
 * too, gi/cut.py with_caustics), and the ray goes on through y's other
 * lobes (glossy, mirror, glass). Emitters and the world are counted only
 * after a rough glossy bounce: direct light is traced separately, and light
 * reaching the point from them through mirrors, glass and near-specular
 * glossy surfaces comes from the caustic map.
 *
 * One work-item per ray (Gather_rays), the cut's lookups for the rays'
 * first diffuse hits made after all rays of a batch are traced, sorted
 * along a Morton curve of their points (Gather_lookup: in ray order each
 * kNN search starts cold; in space order neighbouring searches share their
 * path through the tree, half the time on the CPU device), then one
 * work-item per sample point (Gather_reduce) sums its rays to its
 * irradiance (with cosine sampling, the mean of albedo(y) E(y)), the
 * harmonic mean distance of its hits, its hit count and its gradient. */
#include "device/launch.h"
#include "device/rng.h"
#include "device/sampling.h"
#include "shading/surface.h"
#include "gi/cut_lookup.h"

/* Light sources a gather ray sees after a rough glossy bounce (emitters
 * reached through singular or near-singular ones are the caustic map's). */
inline float3 Gather_lights_seen(const SceneView *sc, float3 org, float3 dir, float tmax, bool escaped) {
    float3 sum = (float3)(0.0f);
    float pdf;
    for (int i = 0; i < sc->light_count; ++i) {
        Light l = sc->lights[i];
        sum += Light_seen(&l, org, dir, 0.0f, tmax, &pdf);
        if (escaped) sum += Light_sun_seen(&l, dir, &pdf);
    }
    return escaped ? sum + sc->world.xyz : sum;
}

/* A ray's first lookup of the cut, made after all rays are traced (in
 * space order, Gather_lookup): the surface point, its shading normal and
 * the weight of its light (w = 1 where there is one, 0 where none). */
typedef struct {
    float3 p, n;
    float4 weight;
} GatherLookup;

/* Ray r of sample s (at p, normal n): the radiance arriving along it (times
 * pi: albedo(y) E(y) at each surface y with a diffuse lobe, through the
 * glossy and singular lobes it meets), the distance of its first hit where
 * it reached a diffuse surface (< 0 where not), and that of its first hit
 * of any surface (INFINITY where none). The rays split the unit square into
 * strata x strata cells, one jittered point each: cell (j, k) = (r % strata,
 * r / strata) is the ring sin^2 theta in [j, j + 1) / strata of the polar
 * angle and the sector phi in 2 pi [k, k + 1) / strata. The light of the
 * first diffuse hit is not in the radiance returned: its lookup is left in
 * *deferred (the cut's lookups of later hits are made here). */
inline float3 Gather_ray(const SceneView *sc, const Cut *cut, int max_specular, float3 p, float3 n, int s, int r,
                         int strata, uint seed, float *distance, float *first_hit, GatherLookup *deferred) {
    float3 sum = (float3)(0.0f);
    *distance = -1.0f;
    *first_hit = INFINITY;
    Rng rng = Rng_make((uint)s, (uint)r, seed);
    float u1 = ((float)(r % strata) + Rng_next(&rng)) / (float)strata;
    float u2 = ((float)(r / strata) + Rng_next(&rng)) / (float)strata;
    float3 dir = Sampling_cosine(n, u1, u2);
    float3 org = p + Ray_offset(Ray_magnitude(p)) * n;
    float3 throughput = (float3)(1.0f);
    float first_t = -1.0f;
    bool rough = false; /* the last bounce was rough glossy: light sources count */
    for (int bounce = 0; bounce <= max_specular; ++bounce) {
        Hit hit;
        bool found = KdTree_intersect(&sc->tree, org, dir, 0.0f, RAY_FAR, &hit);
        if (rough) sum += throughput * PI_F * Gather_lights_seen(sc, org, dir, found ? hit.t : RAY_FAR, !found);
        if (!found) return sum;
        if (bounce == 0) first_t = *first_hit = hit.t;
        SurfacePoint sp = Surface_at(sc, dir, &hit);
        Material m = Surface_material(sc, sp.tri, sp.uv, SURFACE_MIX_U(&rng));
        if (rough) sum += throughput * PI_F * m.emission.xyz;
        float3 base = Surface_textured(sc, &m, &sp);
        Bsdf f = Surface_bsdf(&sp, &m, base, dir, BSDF_SAMPLE_GLOSSY);
        if (f.diffuse.x > 0.0f || f.diffuse.y > 0.0f || f.diffuse.z > 0.0f) {
            /* a diffuse lobe: its light from the cut */
            *distance = first_t;
            float3 weight = throughput * f.diffuse * m.base_color.w;
            if (deferred->weight.w == 0.0f) {
                deferred->p = sp.p;
                deferred->n = sp.ns;
                deferred->weight = (float4)(weight, 1.0f);
            } else {
                sum += weight * CutLookup_light(cut, sp.p, sp.ns);
            }
        }
        /* the other lobes carry the ray on */
        float3 wi, weight;
        float pdf;
        /* drawn in a fixed order (a call's arguments are evaluated in none) */
        float u_lobe = Rng_next(&rng), v1 = Rng_next(&rng), v2 = Rng_next(&rng), v3 = Rng_next(&rng);
        int label = Bsdf_sample(&f, u_lobe, v1, v2, v3, &wi, &weight, &pdf);
        if (label == 0) return sum;
        throughput *= weight;
        rough = (label & BSDF_LABEL_GLOSSY) && f.rough >= CAUSTIC_ROUGHNESS;
        dir = Bsdf_to_world(&f, wi);
        org = Surface_leave(&sp, dir);
    }
    return sum;
}

/* Ward and Heckbert's translational irradiance gradient of a sample from
 * its gather cells (radiance L and first-hit distance r of cell (j, k) at
 * cell[k M + j], M = strata rings and sectors): as the point moves in the
 * tangent plane, the borders between neighbouring cells sweep over what
 * they see, the light of one cell taking the place of the other's. A
 * border between rings j - 1 and j, at theta_j, moves by cos(theta_j) / r per
 * unit of motion along the sector's middle direction u_k, over a projected
 * solid angle of (2 pi / M) sin(theta_j) cos(theta_j); one between sectors
 * k - 1 and k moves by 1 / (r sin theta) along its normal v_k, over
 * (sin theta_j+1 - sin theta_j) / r in all, r the nearer of the two cells'
 * distances. (The rotational gradient, measured too, changed no demo
 * scene's error: their cache points lie on flat surfaces.) The sum over
 * the cells in the tangent frame: (x, y) per colour channel, of pi L. */
inline void Gather_gradient(const __global float4 *cell, int strata, float2 *grad) {
    float inv_m = 1.0f / (float)strata, sector = 2.0f * PI_F * inv_m;
    for (int c = 0; c < 3; ++c) grad[c] = (float2)(0.0f);
    for (int k = 0; k < strata; ++k) {
        /* sector k: the normal of its border with the sector before, its middle direction */
        float2 v_k = (float2)(-sin((float)k * sector), cos((float)k * sector));
        float mid = ((float)k + 0.5f) * sector;
        float2 u_k = (float2)(cos(mid), sin(mid));
        for (int j = 0; j < strata; ++j) {
            int q = k * strata + j;
            float4 here = cell[q];
            float sin_lo = sqrt((float)j * inv_m), sin_hi = sqrt((float)(j + 1) * inv_m);
            /* the border with the sector before, in the same ring */
            float4 before = cell[((k + strata - 1) % strata) * strata + j];
            float across = (sin_hi - sin_lo) / fmin(here.w, before.w);
            float3 step_phi = (here.xyz - before.xyz) * (isfinite(across) ? across : 0.0f);
            /* the border with the ring inside, in the same sector */
            float3 step_theta = (float3)(0.0f);
            if (j > 0) {
                float4 inner = cell[q - 1];
                float along = sector * sin_lo * (1.0f - (float)j * inv_m) / fmin(here.w, inner.w);
                step_theta = (here.xyz - inner.xyz) * (isfinite(along) ? along : 0.0f);
            }
            grad[0] += step_theta.x * u_k + step_phi.x * v_k;
            grad[1] += step_theta.y * u_k + step_phi.y * v_k;
            grad[2] += step_theta.z * u_k + step_phi.z * v_k;
        }
    }
}

/* The bits of v (10 of them) spread to every third place: a Morton code's x. */
inline uint Gather_spread(uint v) {
    v = (v | (v << 16)) & 0x030000FFu;
    v = (v | (v << 8)) & 0x0300F00Fu;
    v = (v | (v << 4)) & 0x030C30C3u;
    return (v | (v << 2)) & 0x09249249u;
}

/* The Morton code (GATHER_KEY_BITS per axis) of p in the cube of half-side
 * `extent` around the origin. */
inline uint Gather_key(float3 p, float extent) {
    float cells = (float)(1 << GATHER_KEY_BITS);
    float3 c = clamp((p / extent * 0.5f + 0.5f) * cells, 0.0f, cells - 1.0f);
    uint3 q = convert_uint3(c);
    return Gather_spread(q.x) | (Gather_spread(q.y) << 1) | (Gather_spread(q.z) << 2);
}

/* Work-item g traces ray r = g % rays of sample s = first + g / rays, for
 * the count samples from first. The ray's radiance but its first diffuse
 * hit's light, and its first-hit distance, go to cells[g], the distance of
 * its first diffuse hit (< 0 where none) to distances[g], the lookup left
 * for that hit to lookup_*[g] and the Morton code of its point to keys[g]
 * (0 where none; `extent`: the half-side of a cube around the scene). */
__kernel void Gather_rays(SCENE_PARAMS, CUT_PARAMS, const __global float4 *sample_pos,
                          const __global float4 *sample_nrm, const int first, const int count, const int strata,
                          const int max_specular, const uint seed, const float extent, __global float4 *cells,
                          __global float *distances, __global float4 *lookup_pos, __global float4 *lookup_nrm,
                          __global float4 *lookup_weight, __global uint *keys) {
    int g = Launch_global_id(), rays = strata * strata;
    if (g >= count * rays) return;
    int s = first + g / rays, r = g % rays;
    SceneView sc = SCENE_MAKE();
    Cut cut = CUT_MAKE();
    float t, first_hit;
    GatherLookup deferred = {(float3)(0.0f), (float3)(0.0f), (float4)(0.0f)};
    float3 radiance = Gather_ray(&sc, &cut, max_specular, sample_pos[s].xyz, sample_nrm[s].xyz, s, r, strata, seed,
                                 &t, &first_hit, &deferred);
    cells[g] = (float4)(radiance, first_hit);
    distances[g] = t;
    lookup_pos[g] = (float4)(deferred.p, 0.0f);
    lookup_nrm[g] = (float4)(deferred.n, 0.0f);
    lookup_weight[g] = deferred.weight;
    keys[g] = deferred.weight.w != 0.0f ? Gather_key(deferred.p, extent) : 0u;
}

/* The lookups Gather_rays left, in space order (order[j]: the ray of the
 * j-th smallest key, j < n), so that neighbouring work-items search
 * neighbouring parts of the cut's tree: each ray's light added to its cell. */
__kernel void Gather_lookup(CUT_PARAMS, const __global int *order, const int n, const __global float4 *lookup_pos,
                            const __global float4 *lookup_nrm, const __global float4 *lookup_weight,
                            __global float4 *cells) {
    int j = Launch_global_id();
    if (j >= n) return;
    int slot = order[j];
    float4 w = lookup_weight[slot];
    if (w.w == 0.0f) return;
    Cut cut = CUT_MAKE();
    float3 light = w.xyz * CutLookup_light(&cut, lookup_pos[slot].xyz, lookup_nrm[slot].xyz);
    cells[slot].xyz += light;
}

/* Work-item i reduces the rays of sample s = first + i, for the count
 * samples from first (their rays at cells[i rays ...]). Outputs per
 * sample: irradiance (rgb), harmonic mean hit distance (INFINITY when no
 * ray hit), hits, and its translational gradient (Gather_gradient) as three
 * rows dE/dx, dE/dy, dE/dz, rgb each. */
__kernel void Gather_reduce(const __global float4 *sample_nrm, const int first, const int count, const int strata,
                            const __global float4 *cells, const __global float *distances,
                            __global float4 *out_irradiance, __global float *out_distance, __global int *out_hits,
                            __global float4 *out_gradient) {
    int i = Launch_global_id(), rays = strata * strata;
    if (i >= count) return;
    const __global float4 *cell = cells + (size_t)i * rays; /* this sample's */
    const __global float *distance = distances + (size_t)i * rays;
    float3 sum = (float3)(0.0f);
    float inv_distance = 0.0f;
    int hits = 0;
    for (int r = 0; r < rays; ++r) {
        sum += cell[r].xyz;
        float t = distance[r];
        if (t >= 0.0f) {
            inv_distance += 1.0f / fmax(t, 1e-30f);
            hits++;
        }
    }
    float2 grad[3];
    Gather_gradient(cell, strata, grad);
    int s = first + i;
    out_irradiance[s] = (float4)(sum / (float)rays, 0.0f);
    out_distance[s] = hits > 0 ? (float)hits / inv_distance : INFINITY;
    out_hits[s] = hits;
    /* the cells hold pi L: the gradient in the world is the sum / pi */
    float3 t, b;
    Sampling_frame(sample_nrm[s].xyz, &t, &b);
    float3 g[3];
    for (int c = 0; c < 3; ++c) g[c] = (grad[c].x * t + grad[c].y * b) * (1.0f / PI_F);
    out_gradient[3 * s + 0] = (float4)(g[0].x, g[1].x, g[2].x, 0.0f);
    out_gradient[3 * s + 1] = (float4)(g[0].y, g[1].y, g[2].y, 0.0f);
    out_gradient[3 * s + 2] = (float4)(g[0].z, g[1].z, g[2].z, 0.0f);
}
