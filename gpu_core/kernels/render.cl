/* The image kernel (the reference path tracer): camera paths through mirrors
 * and glass to diffuse surfaces, which take direct light from every light
 * with shadow rays and, with diffuse bounces, path-traced indirect light;
 * the light is also split into Blender's light passes. */
#include "types.h"
#include "rng.h"
#include "sampling.h"
#include "camera.h"
#include "ray.h"
#include "lights.h"
#include "bsdf.h"
#include "texture.h"
#include "kdtree_traverse.h"
#include "surface.h"

#define RENDER_MAX_PASSTHROUGH 64
#define RENDER_GI_MIN_COS 0.7f /* a shading point stands for surfaces facing within about 45 degrees */

/* Fraction of light passing along a shadow ray: 0 when an opaque surface
 * blocks it; with see-through (alpha) materials in the scene, the product of
 * their transparencies. */
inline float Render_visibility(const KdTree *tree, const __global int *tri_material,
                               const __global Material *materials, float3 org, float3 dir,
                               float tmax) {
#ifdef RENDER_HAS_ALPHA
    float vis = 1.0f, tmin = 0.0f;
    for (int i = 0; i < RENDER_MAX_PASSTHROUGH; ++i) {
        Hit hit;
        if (!KdTree_intersect(tree, org, dir, tmin, tmax, &hit)) return vis;
        float alpha = materials[tri_material[hit.tri]].base_color.w;
        if (alpha >= 1.0f) return 0.0f;
        vis *= 1.0f - alpha;
        tmin = hit.t + Ray_offset(fmax(hit.t, Ray_magnitude(org)));
    }
    return 0.0f;
#else
    return KdTree_occluded(tree, org, dir, 0.0f, tmax) ? 0.0f : 1.0f;
#endif
}

/* Direct light at a diffuse point from every light, world included:
 * light_samples shadow rays per light, averaged. Shadow rays leave from just
 * above the surface on the side the path arrived from (ng). */
inline float3 Render_direct(const KdTree *tree, const __global int *tri_material,
                            const __global Material *materials, const __global Light *lights,
                            int light_count, const Emitters *em, float3 world,
                            const SurfacePoint *sp, int light_samples, Rng *rng) {
    float3 sum = (float3)(0.0f);
    float3 org = sp->p + sp->eps * sp->ng;
    bool has_world = world.x > 0.0f || world.y > 0.0f || world.z > 0.0f;
    for (int k = 0; k < light_samples; ++k) {
        for (int i = 0; i < light_count; ++i) {
            Light l = lights[i];
            float u0 = Rng_next(rng), u1 = Rng_next(rng), u2 = Rng_next(rng);
            /* sample from the offset origin so the shadow ray ends at the light */
            LightSample ls = Light_sample(&l, em, org, sp->ns, u0, u1, u2);
            if (!(ls.value.x > 0.0f || ls.value.y > 0.0f || ls.value.z > 0.0f) || !(ls.dist > 0.0f)) continue;
            sum += ls.value * Render_visibility(tree, tri_material, materials, org, ls.dir, ls.dist);
        }
        if (has_world) {
            LightSample ls = Light_sample_world(world, sp->ns, Rng_next(rng), Rng_next(rng));
            sum += ls.value * Render_visibility(tree, tri_material, materials, org, ls.dir, LIGHT_FAR);
        }
    }
    return sum / (float)light_samples;
}

/* Radiance of the lights a specular ray passes before tmax; an
 * escaping ray also sees sun disks. */
inline float3 Render_lights_seen(const __global Light *lights, int light_count, float3 org, float3 dir,
                                 float tmax, bool escaped) {
    float3 sum = (float3)(0.0f);
    for (int i = 0; i < light_count; ++i) {
        Light l = lights[i];
        sum += Light_seen(&l, org, dir, tmax);
        if (escaped) sum += Light_sun_seen(&l, dir);
    }
    return sum;
}

/* Light passes, with Cycles' meaning: a path's light goes to the pass of
 * the lobe its first scattering event took (diffuse, glossy = mirror and
 * glass reflection, transmission = glass refraction), "direct" when it
 * arrived after that one event and "indirect" after more; light seen before
 * any scattering is Emission (surfaces) or Environment (the world). Passes
 * 0..7 add up to Combined. Caustics repeats the part of them that reached a
 * diffuse surface through specular events (light no shadow ray can sample). */
#define PASS_DIFFUSE 0 /* +0 direct, +1 indirect */
#define PASS_GLOSSY 2
#define PASS_TRANSMISSION 4
#define PASS_EMISSION 6
#define PASS_ENVIRONMENT 7
#define PASS_CAUSTICS 8
#define PASS_SUMMED 8 /* passes before this one make up Combined */
#define PASS_COUNT 9

/* What the kernel writes besides Combined, Depth and Normal (flags). */
#define OUTPUT_LIGHT_PASSES 1
#define OUTPUT_DENOISING 2

/* Add light c, which arrived after `events` scattering events, to its pass. */
inline void Render_add(float3 *light, float3 c, int first_pass, int events, bool environment, bool caustic) {
    int p = events == 0 ? (environment ? PASS_ENVIRONMENT : PASS_EMISSION) : first_pass + (events > 1 ? 1 : 0);
    light[p] += c;
    if (caustic) light[PASS_CAUSTICS] += c;
}

#ifdef RENDER_GI
/* GI mode: the cached irradiance at the shading point that stands for
 * surface point p (normal n) on pixel (wx, wy) of the window: among the
 * points of this pixel and its eight neighbours, the nearest one facing the
 * same way. False where none does (a surface no shading ray found). */
inline bool Render_gi_lookup(const __global float4 *gi_pos, const __global float4 *gi_nrm,
                             const __global float4 *gi_indirect, const __global float4 *gi_caustic,
                             int sub, int4 window, int wx, int wy, float3 p, float3 n,
                             float3 *indirect, float3 *caustic) {
    int best = -1;
    float best_d2 = INFINITY;
    for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
            int x = wx + dx, y = wy + dy;
            if (x < 0 || y < 0 || x >= window.x || y >= window.y) continue;
            int first = (y * window.x + x) * sub * sub;
            for (int k = first; k < first + sub * sub; ++k) {
                float4 q = gi_pos[k];
                if (q.w <= 0.0f || dot(gi_nrm[k].xyz, n) < RENDER_GI_MIN_COS) continue;
                float3 d = q.xyz - p;
                float d2 = dot(d, d);
                if (d2 < best_d2) {
                    best_d2 = d2;
                    best = k;
                }
            }
        }
    }
    if (best < 0) return false;
    *indirect = gi_indirect[best].xyz;
    *caustic = gi_caustic[best].xyz;
    return true;
}
#endif

/* A direction in camera space (x right, y up, z back), as Cycles stores the
 * denoising normal. */
inline float3 Render_to_camera(const Camera *cam, float3 d) {
    return (float3)(dot(d, cam->right.xyz), dot(d, cam->up.xyz), dot(d, cam->back.xyz));
}

/* One work item per pixel of the batch; all samples of the pixel.
 * window = (width, height, pixels in this batch, first pixel of the batch)
 * of the render window, whose lower-left pixel is window_origin. Light
 * passes are stored pass after pass, each the size of the window. */
__kernel void Render_pixels(KDTREE_PARAMS, const __global float4 *tri_normals,
                            const __global float2 *tri_uvs, const __global int *tri_material,
                            const __global Material *materials, const __global Light *lights,
                            const int light_count, const __global int *emit_tris,
                            const __global float *emit_cdf, const int emit_count,
                            const __global float4 *tex_atlas, const __global TextureInfo *tex_infos,
                            const __global Camera *camera_buf, const float4 world,
                            const int4 window, const int2 window_origin, const int samples, const int max_bounces,
                            const int max_diffuse, const int light_samples,
                            const uint seed, const float clamp_value, const int outputs,
                            __global float4 *out_combined, __global float *out_depth,
                            __global float4 *out_normal, __global float4 *out_light,
                            __global float4 *out_albedo, __global float4 *out_feature_normal,
                            const __global float4 *gi_pos, const __global float4 *gi_nrm,
                            const __global float4 *gi_indirect, const __global float4 *gi_caustic,
                            const int gi_sub) {
    int i = get_global_id(0);
    int g = window.w + i; /* index in the render window */
    int window_pixels = window.x * window.y;
    if (i >= window.z || g >= window_pixels) return;
    KdTree tree = KDTREE_MAKE();
    Emitters em = {emit_tris, emit_cdf, emit_count, kd_verts, tri_material, materials};
    Camera cam = *camera_buf;
    int wx = g % window.x, wy = g / window.x;
    int px = window_origin.x + wx, py = window_origin.y + wy;
    float3 sky = world.xyz;
    bool transparent = world.w > 0.0f;

    float3 pixel_light[PASS_COUNT];
    for (int p = 0; p < PASS_COUNT; ++p) pixel_light[p] = (float3)(0.0f);
    float alpha_sum = 0.0f;
    float depth = 1e10f;
    float3 normal = (float3)(0.0f);
    float3 albedo_sum = (float3)(0.0f), feature_normal_sum = (float3)(0.0f);
    /* anti-aliasing: the pixel's samples follow the R2 sequence from a
     * random offset, so they cover its area evenly */
    uint pixel_id = (uint)(py * cam.width + px);
    uint aa_x = Rng_hash(pixel_id ^ Rng_hash(seed ^ 0xa511e9b3U));
    uint aa_y = Rng_hash(aa_x);
    for (int s = 0; s < samples; ++s) {
        Rng rng = Rng_make(pixel_id, (uint)s, seed);
        float3 org, dir;
        float tmin, tmax;
        float2 aa = Rng_r2((uint)s, aa_x, aa_y);
        Camera_ray(&cam, px + aa.x, py + aa.y, &org, &dir, &tmin, &tmax);
        float3 throughput = (float3)(1.0f);
        float3 light[PASS_COUNT];
        for (int p = 0; p < PASS_COUNT; ++p) light[p] = (float3)(0.0f);
        float alpha = 1.0f;
        int bounces = 0, diffuse = 0, passes = 0;
        int first_pass = PASS_DIFFUSE;
        /* a specular event since the last diffuse one (and there was one) */
        bool caustic = false;
        /* the denoiser's albedo and normal: at the first diffuse event, or
         * the world, seen through the specular events before it */
        bool features_done = false;
        while (true) {
            Hit hit;
            bool found = KdTree_intersect(&tree, org, dir, tmin, tmax, &hit);
            /* emitters hit by the path count unless a shadow ray already
             * sampled them (next-event estimation at a diffuse event): before
             * any diffuse event, or after specular events that followed one */
            bool unsampled = diffuse == 0 || caustic;
            /* lights are see-through emitters: add those before the surface.
             * As in Cycles by default, only scattered rays see them, not the
             * camera */
            if (bounces > 0 && unsampled && light_count > 0) {
                float3 seen = Render_lights_seen(lights, light_count, org, dir, found ? hit.t : tmax, !found);
                Render_add(light, throughput * seen, first_pass, bounces, false, caustic);
            }
            if (!found) {
                if (bounces == 0 && passes == 0 && transparent) alpha = 0.0f;
                else if (unsampled) Render_add(light, throughput * sky, first_pass, bounces, true, caustic);
                if (!features_done) albedo_sum += throughput;
                break;
            }
            SurfacePoint sp = Surface_at(&tree, tri_normals, tri_uvs, tri_material, dir, &hit);
            Material m = materials[sp.material];
            float3 base = m.base_color.xyz;
            float mat_alpha = m.base_color.w;
#ifdef RENDER_HAS_TEXTURES
            if (m.texture >= 0) base *= Texture_sample(tex_atlas, tex_infos, m.texture, sp.uv).xyz;
#endif
            /* stochastic alpha: pass straight through */
            if (mat_alpha < 1.0f && Rng_next(&rng) >= mat_alpha && passes < RENDER_MAX_PASSTHROUGH) {
                passes++;
                org = sp.p - sp.eps * sp.ng;
                tmin = 0.0f;
                tmax = RAY_FAR;
                continue;
            }
            if (bounces == 0 && s == 0) {
                depth = Camera_depth(&cam, sp.p);
                normal = sp.ns;
            }
            if (unsampled) Render_add(light, throughput * m.emission.xyz, first_pass, bounces, false, caustic);
            int lobe = Bsdf_pick(&m, Rng_next(&rng));
            if (lobe == BSDF_DIFFUSE) {
                if (bounces == 0) first_pass = PASS_DIFFUSE;
                if (!features_done) {
                    albedo_sum += throughput * base;
                    feature_normal_sum += Render_to_camera(&cam, sp.ns);
                    features_done = true;
                }
                float3 e = Render_direct(&tree, tri_material, materials, lights, light_count, &em, sky, &sp,
                                         light_samples, &rng);
                Render_add(light, throughput * base * (1.0f / PI_F) * e, first_pass, bounces + 1, false, false);
#ifdef RENDER_GI
                /* GI mode: indirect light and caustics from the cache at the first diffuse event */
                float3 e_indirect, e_caustic;
                if (diffuse == 0 && Render_gi_lookup(gi_pos, gi_nrm, gi_indirect, gi_caustic, gi_sub, window, wx, wy,
                                                     sp.p, sp.ns, &e_indirect, &e_caustic)) {
                    float3 f = throughput * base * (1.0f / PI_F);
                    Render_add(light, f * e_indirect, first_pass, bounces + 2, false, false);
                    Render_add(light, f * e_caustic, first_pass, bounces + 2, false, true);
                }
#endif
                /* path-traced indirect light: cosine sampling cancels the
                 * Lambert cosine/pi, leaving the albedo; Russian roulette
                 * after two diffuse bounces keeps the estimate unbiased */
                if (diffuse >= max_diffuse || bounces >= max_bounces + max_diffuse) break;
                throughput *= base;
                if (diffuse >= 2) {
                    float q = fmin(fmax(fmax(throughput.x, throughput.y), throughput.z), 0.95f);
                    if (Rng_next(&rng) >= q) break;
                    throughput /= q;
                }
                dir = Sampling_cosine(sp.ns, Rng_next(&rng), Rng_next(&rng));
                if (dot(dir, sp.ng) <= 0.0f) break;
                org = sp.p + sp.eps * sp.ng;
                tmin = 0.0f;
                tmax = RAY_FAR;
                caustic = false;
                diffuse++;
                bounces++;
                continue;
            }
            if (bounces >= max_bounces + max_diffuse) break;
            bool refracted;
            float u = lobe == BSDF_GLASS ? Rng_next(&rng) : 0.0f;
            throughput *= Surface_specular(&sp, &m, lobe, base, u, &dir, &org, &refracted);
            if (bounces == 0) first_pass = refracted ? PASS_TRANSMISSION : PASS_GLOSSY;
            caustic = diffuse > 0;
            tmin = 0.0f;
            tmax = RAY_FAR;
            bounces++;
        }
        /* the clamp scales every pass of the sample alike, so they still
         * add up to Combined; a non-finite sample is dropped */
        float3 radiance = (float3)(0.0f);
        for (int p = 0; p < PASS_SUMMED; ++p) radiance += light[p];
        if (isfinite(radiance.x) && isfinite(radiance.y) && isfinite(radiance.z)) {
            float3 scale = (float3)(1.0f);
            if (clamp_value > 0.0f) scale = fmin(radiance, (float3)(clamp_value)) / fmax(radiance, (float3)(1e-30f));
            for (int p = 0; p < PASS_COUNT; ++p) pixel_light[p] += light[p] * scale;
        }
        alpha_sum += alpha;
    }
    float inv = 1.0f / (float)samples;
    float3 total = (float3)(0.0f);
    for (int p = 0; p < PASS_SUMMED; ++p) total += pixel_light[p];
    out_combined[g] = (float4)(total * inv, alpha_sum * inv);
    out_depth[g] = depth;
    out_normal[g] = (float4)(normal, 0.0f);
    if (outputs & OUTPUT_LIGHT_PASSES) {
        for (int p = 0; p < PASS_COUNT; ++p) out_light[p * window_pixels + g] = (float4)(pixel_light[p] * inv, 0.0f);
    }
    if (outputs & OUTPUT_DENOISING) {
        out_albedo[g] = (float4)(albedo_sum * inv, 0.0f);
        out_feature_normal[g] = (float4)(feature_normal_sum * inv, 0.0f);
    }
}
