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
 * One work-group of GATHER_GROUP work-items per sample point: its rays are
 * spread over the group and reduced in local memory to the sample's
 * irradiance (with cosine sampling, the mean of albedo(y) E(y)), the
 * harmonic mean distance of its hits, and its hit count. */
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

/* Ray r of sample s (at p, normal n): the radiance arriving along it (times
 * pi: albedo(y) E(y) at each surface y with a diffuse lobe, through the
 * glossy and singular lobes it meets), the distance of its first hit where
 * it reached a diffuse surface (< 0 where not), and that of its first hit
 * of any surface (INFINITY where none). The rays split the unit square into
 * strata x strata cells, one jittered point each: cell (j, k) = (r % strata,
 * r / strata) is the ring sin^2 theta in [j, j + 1) / strata of the polar
 * angle and the sector phi in 2 pi [k, k + 1) / strata. */
inline float3 Gather_ray(const SceneView *sc, const Cut *cut, int max_specular, float3 p, float3 n, int s, int r,
                         int strata, uint seed, float *distance, float *first_hit) {
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
            sum += throughput * f.diffuse * m.base_color.w * CutLookup_light(cut, sp.p, sp.ns);
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
 * scene's error: their cache points lie on flat surfaces.) This work-item's
 * share of the cells, summed in the tangent frame: (x, y) per colour
 * channel, of pi L. */
inline void Gather_gradient_share(const __global float4 *cell, int strata, int lid, float2 *grad) {
    int rays = strata * strata;
    float inv_m = 1.0f / (float)strata, sector = 2.0f * PI_F * inv_m;
    for (int c = 0; c < 3; ++c) grad[c] = (float2)(0.0f);
    for (int q = lid; q < rays; q += GATHER_GROUP) {
        int j = q % strata, k = q / strata;
        float4 here = cell[q];
        float sin_lo = sqrt((float)j * inv_m), sin_hi = sqrt((float)(j + 1) * inv_m);
        /* the border with the sector before, in the same ring */
        float4 before = cell[((k + strata - 1) % strata) * strata + j];
        float across = (sin_hi - sin_lo) / fmin(here.w, before.w);
        float2 v_k = (float2)(-sin((float)k * sector), cos((float)k * sector));
        float3 step_phi = (here.xyz - before.xyz) * (isfinite(across) ? across : 0.0f);
        /* the border with the ring inside, in the same sector */
        float3 step_theta = (float3)(0.0f);
        float mid = ((float)k + 0.5f) * sector;
        float2 u_k = (float2)(cos(mid), sin(mid));
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

/* Work-group g gathers sample first + g, for the samples before end (a
 * launch's grid may hold a few groups more). Outputs per sample:
 * irradiance (rgb), harmonic mean hit distance (INFINITY when no ray hit),
 * hits, and its translational gradient (Gather_gradient_share) as three
 * rows dE/dx, dE/dy, dE/dz, rgb each. Each ray's radiance and first-hit
 * distance pass through cells (strata^2 per sample of the launch). */
__kernel void Gather_samples(SCENE_PARAMS, CUT_PARAMS, const __global float4 *sample_pos, const __global float4 *sample_nrm,
                             const int first, const int end, const int strata, const int max_specular,
                             const uint seed, __global float4 *cells, __global float4 *out_irradiance,
                             __global float *out_distance, __global int *out_hits, __global float4 *out_gradient) {
    __local float4 sum_s[GATHER_GROUP];
    __local int hits_s[GATHER_GROUP];
    __local float2 grad_s[3][GATHER_GROUP];
    int s = first + Launch_group_id(), lid = get_local_id(0);
    int rays = strata * strata;
    __global float4 *cell = cells + (s < end ? (size_t)(s - first) * (size_t)rays : 0); /* this sample's */
    float3 sum = (float3)(0.0f);
    float inv_distance = 0.0f;
    int hits = 0;
    float3 n = (float3)(0.0f, 0.0f, 1.0f);
    if (s < end) {
        SceneView sc = SCENE_MAKE();
        Cut cut = CUT_MAKE();
        float3 p = sample_pos[s].xyz;
        n = sample_nrm[s].xyz;
        for (int r = lid; r < rays; r += GATHER_GROUP) {
            float t, first_hit;
            float3 radiance = Gather_ray(&sc, &cut, max_specular, p, n, s, r, strata, seed, &t, &first_hit);
            sum += radiance;
            cell[r] = (float4)(radiance, first_hit);
            if (t >= 0.0f) {
                inv_distance += 1.0f / fmax(t, 1e-30f);
                hits++;
            }
        }
    }
    barrier(CLK_GLOBAL_MEM_FENCE);
    float2 grad[3] = {(float2)(0.0f), (float2)(0.0f), (float2)(0.0f)};
    if (s < end) Gather_gradient_share(cell, strata, lid, grad);
    sum_s[lid] = (float4)(sum, inv_distance);
    hits_s[lid] = hits;
    for (int c = 0; c < 3; ++c) grad_s[c][lid] = grad[c];
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int step = GATHER_GROUP / 2; step > 0; step /= 2) {
        if (lid < step) {
            sum_s[lid] += sum_s[lid + step];
            hits_s[lid] += hits_s[lid + step];
            for (int c = 0; c < 3; ++c) grad_s[c][lid] += grad_s[c][lid + step];
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0 && s < end) {
        float4 total = sum_s[0];
        out_irradiance[s] = (float4)(total.xyz / (float)rays, 0.0f);
        out_distance[s] = hits_s[0] > 0 ? (float)hits_s[0] / total.w : INFINITY;
        out_hits[s] = hits_s[0];
        /* the cells hold pi L: the gradient in the world is the sum / pi */
        float3 t, b;
        Sampling_frame(n, &t, &b);
        float3 g[3];
        for (int c = 0; c < 3; ++c) g[c] = (grad_s[c][0].x * t + grad_s[c][0].y * b) * (1.0f / PI_F);
        out_gradient[3 * s + 0] = (float4)(g[0].x, g[1].x, g[2].x, 0.0f);
        out_gradient[3 * s + 1] = (float4)(g[0].y, g[1].y, g[2].y, 0.0f);
        out_gradient[3 * s + 2] = (float4)(g[0].z, g[1].z, g[2].z, 0.0f);
    }
}
