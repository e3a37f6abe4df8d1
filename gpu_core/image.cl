/* The image kernel (also the reference path tracer): camera paths through
 * mirrors and glass to diffuse surfaces, which take direct light from every
 * light with shadow rays and, with diffuse bounces, path-traced indirect
 * light; in GI mode (IMAGE_GI) the first diffuse surface also takes the
 * cached indirect light and caustics. The light is split into Blender's
 * light passes (PASS_*, device/constants.py). */
#include "device/rng.h"
#include "device/sampling.h"
#include "shading/camera.h"
#include "shading/surface.h"

#define IMAGE_MAX_PASSTHROUGH 64
#define IMAGE_ALL_LIGHTS 4 /* up to this many lights, every one gets a shadow ray */

/* A path's light is summed per light pass only where the render asks for
 * the passes (IMAGE_LIGHT_PASSES); else in one sum, Combined, which keeps
 * the path's private state small. */
#ifdef IMAGE_LIGHT_PASSES
#define IMAGE_SLOTS PASS_COUNT
#define IMAGE_SUMMED PASS_SUMMED
#else
#define IMAGE_SLOTS 1
#define IMAGE_SUMMED 1
#endif
#define IMAGE_GI_MIN_COS 0.7f /* a shading point stands for surfaces facing within about 45 degrees */

/* The GI cache as the image reads it: per slot of the shading-point grid
 * (gpu_core/gi/shading_points.py), position (w = 1 where a point is),
 * normal, indirect and caustic irradiance. */
#define IMAGE_GI_PARAMS                                                      \
    const __global float4 *gi_pos, const __global float4 *gi_nrm,           \
        const __global float4 *gi_indirect, const __global float4 *gi_caustic

/* Fraction of light passing along a shadow ray: 0 when an opaque surface
 * blocks it; with see-through (alpha) materials in the scene, the product of
 * their transparencies. */
inline float Image_visibility(const SceneView *sc, float3 org, float3 dir, float tmax) {
#ifdef SCENE_HAS_ALPHA
    float vis = 1.0f, tmin = 0.0f;
    for (int i = 0; i < IMAGE_MAX_PASSTHROUGH; ++i) {
        Hit hit;
        if (!KdTree_intersect(&sc->tree, org, dir, tmin, tmax, &hit)) return vis;
        float alpha = sc->materials[sc->material_of[hit.tri]].base_color.w;
        if (alpha >= 1.0f) return 0.0f;
        vis *= 1.0f - alpha;
        tmin = hit.t + Ray_offset(fmax(hit.t, Ray_magnitude(org)));
    }
    return 0.0f;
#else
    return KdTree_occluded(&sc->tree, org, dir, 0.0f, tmax) ? 0.0f : 1.0f;
#endif
}

/* Light from one light sample of light l at a diffuse point, seen through
 * the scene (shadow rays leave from org, above the surface). */
inline float3 Image_light_sample(const SceneView *sc, const Light *l, float3 org, float3 ns, Rng *rng) {
    float u0 = Rng_next(rng), u1 = Rng_next(rng), u2 = Rng_next(rng);
    /* sample from the offset origin so the shadow ray ends at the light */
    LightSample ls = Light_sample(l, &sc->em, org, ns, u0, u1, u2);
    if (!(ls.value.x > 0.0f || ls.value.y > 0.0f || ls.value.z > 0.0f) || !(ls.dist > 0.0f)) return (float3)(0.0f);
    return ls.value * Image_visibility(sc, org, ls.dir, ls.dist);
}

/* The light row a shadow ray goes to with many lights: picked by u in
 * proportion to the power it emits (Light.pick, the inclusive CDF); its
 * probability in *p. */
inline int Image_pick_light(const SceneView *sc, float u, float *p) {
    int i = 0;
    while (i < sc->light_count - 1 && sc->lights[i].pick <= u) ++i;
    *p = sc->lights[i].pick - (i > 0 ? sc->lights[i - 1].pick : 0.0f);
    return i;
}

/* Direct light at a diffuse point, world included: light_samples rounds,
 * averaged. With up to IMAGE_ALL_LIGHTS lights a round sends a shadow ray
 * to every light (the least noise for the rays); with more, one ray to one
 * light picked by power, so a frame's cost does not grow with the number of
 * lights. Shadow rays leave from just above the surface on the side the
 * path arrived from (ng). */
inline float3 Image_direct(const SceneView *sc, const SurfacePoint *sp, int light_samples, Rng *rng) {
    float3 sum = (float3)(0.0f);
    float3 org = sp->p + sp->eps * sp->ng;
    bool has_world = Scene_has_world(sc);
    for (int k = 0; k < light_samples; ++k) {
        if (sc->light_count <= IMAGE_ALL_LIGHTS) {
            for (int i = 0; i < sc->light_count; ++i) {
                Light l = sc->lights[i];
                sum += Image_light_sample(sc, &l, org, sp->ns, rng);
            }
        } else {
            float p;
            Light l = sc->lights[Image_pick_light(sc, Rng_next(rng), &p)];
            if (p > 0.0f) sum += Image_light_sample(sc, &l, org, sp->ns, rng) / p;
        }
        if (has_world) {
            LightSample ls = Light_sample_world(sc->world.xyz, sp->ns, Rng_next(rng), Rng_next(rng));
            sum += ls.value * Image_visibility(sc, org, ls.dir, LIGHT_FAR);
        }
    }
    return sum / (float)light_samples;
}

/* Radiance of the lights a specular ray passes before tmax; an
 * escaping ray also sees sun disks. */
inline float3 Image_lights_seen(const SceneView *sc, float3 org, float3 dir, float tmax, bool escaped) {
    float3 sum = (float3)(0.0f);
    for (int i = 0; i < sc->light_count; ++i) {
        Light l = sc->lights[i];
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
 * before PASS_SUMMED add up to Combined. Caustics repeats the part of them
 * that reached a diffuse surface through specular events (light no shadow
 * ray can sample). Add light c, which arrived after `events` scattering
 * events, to its pass. */
inline void Image_add(float3 *light, float3 c, int first_pass, int events, bool environment, bool caustic) {
#ifdef IMAGE_LIGHT_PASSES
    int p = events == 0 ? (environment ? PASS_ENVIRONMENT : PASS_EMISSION) : first_pass + (events > 1 ? 1 : 0);
    light[p] += c;
    if (caustic) light[PASS_CAUSTICS] += c;
#else
    light[0] += c;
#endif
}

#ifdef IMAGE_GI
/* GI mode: the cached irradiance at the shading point that stands for
 * surface point p (normal n) on pixel (wx, wy) of the window (w x h): among
 * the points of this pixel and its eight neighbours, the nearest one facing
 * the same way. False where none does (a surface no shading ray found). */
inline bool Image_gi_lookup(IMAGE_GI_PARAMS, int sub, int w, int h, int wx, int wy, float3 p, float3 n,
                            float3 *indirect, float3 *caustic) {
    int best = -1;
    float best_d2 = INFINITY;
    for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
            int x = wx + dx, y = wy + dy;
            if (x < 0 || y < 0 || x >= w || y >= h) continue;
            int first = (y * w + x) * sub * sub;
            for (int k = first; k < first + sub * sub; ++k) {
                float4 q = gi_pos[k];
                if (q.w <= 0.0f || dot(gi_nrm[k].xyz, n) < IMAGE_GI_MIN_COS) continue;
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
inline float3 Image_to_camera(const Camera *cam, float3 d) {
    return (float3)(dot(d, cam->right.xyz), dot(d, cam->up.xyz), dot(d, cam->back.xyz));
}

/* What one camera path brings its pixel. */
typedef struct {
    float3 light[IMAGE_SLOTS]; /* by pass (or one sum) */
    float alpha;              /* 0 where a transparent film shows the world */
    float3 albedo;            /* denoising albedo: at the first diffuse event, or the world */
    float3 feature_normal;    /* denoising normal (camera space), at the first diffuse event */
    float depth;              /* of the first surface hit (1e10 when none) */
    float3 normal;            /* its shading normal */
} ImagePath;

/* Where a camera path is: its ray, what it carries, what it went through. */
typedef struct {
    float3 org, dir;
    float tmin, tmax;
    float3 throughput;
    int bounces, diffuse, passes;
    int first_pass;      /* the pass of its first scattering event */
    bool caustic;        /* a specular event since the last diffuse one (and there was one) */
    bool features_done;  /* the denoising features are taken */
} ImageState;

/* The path leaves from p along dir, a new segment. */
inline void Image_continue(ImageState *st, float3 p, float3 dir) {
    st->org = p;
    st->dir = dir;
    st->tmin = 0.0f;
    st->tmax = RAY_FAR;
}

/* A diffuse event at sp: direct light, GI mode's cached light at the first
 * one, then a path-traced bounce while diffuse bounces are left. Returns
 * whether the path goes on. */
inline bool Image_diffuse_event(const SceneView *sc, const Camera *cam, const ImageJob *job, IMAGE_GI_PARAMS,
                                int wx, int wy, const SurfacePoint *sp, float3 base, Rng *rng, ImageState *st,
                                ImagePath *path) {
    if (st->bounces == 0) st->first_pass = PASS_DIFFUSE;
    if (!st->features_done) {
        path->albedo = st->throughput * base;
        path->feature_normal = Image_to_camera(cam, sp->ns);
        st->features_done = true;
    }
    float3 e = Image_direct(sc, sp, job->light_samples, rng);
    Image_add(path->light, st->throughput * base * (1.0f / PI_F) * e, st->first_pass, st->bounces + 1, false, false);
#ifdef IMAGE_GI
    /* GI mode: indirect light and caustics from the cache at the first diffuse event */
    float3 e_indirect, e_caustic;
    if (st->diffuse == 0 && Image_gi_lookup(gi_pos, gi_nrm, gi_indirect, gi_caustic, job->gi_subpixels,
                                            job->window.x, job->window.y, wx, wy, sp->p, sp->ns, &e_indirect,
                                            &e_caustic)) {
        float3 f = st->throughput * base * (1.0f / PI_F);
        Image_add(path->light, f * e_indirect, st->first_pass, st->bounces + 2, false, false);
        Image_add(path->light, f * e_caustic, st->first_pass, st->bounces + 2, false, true);
    }
#endif
    /* path-traced indirect light: cosine sampling cancels the Lambert
     * cosine/pi, leaving the albedo; Russian roulette after two diffuse
     * bounces keeps the estimate unbiased */
    if (st->diffuse >= job->max_diffuse || st->bounces >= job->max_bounces + job->max_diffuse) return false;
    st->throughput *= base;
    if (st->diffuse >= 2) {
        float q = fmin(fmax(fmax(st->throughput.x, st->throughput.y), st->throughput.z), 0.95f);
        if (Rng_next(rng) >= q) return false;
        st->throughput /= q;
    }
    float3 dir = Sampling_cosine(sp->ns, Rng_next(rng), Rng_next(rng));
    if (dot(dir, sp->ng) <= 0.0f) return false;
    Image_continue(st, sp->p + sp->eps * sp->ng, dir);
    st->caustic = false;
    st->diffuse++;
    st->bounces++;
    return true;
}

/* A specular event (mirror, or glass reflection or refraction) at sp.
 * Returns whether the path goes on. */
inline bool Image_specular_event(const ImageJob *job, const SurfacePoint *sp, const Material *m, int lobe,
                                 float3 base, Rng *rng, ImageState *st) {
    if (st->bounces >= job->max_bounces + job->max_diffuse) return false;
    bool refracted;
    float u = lobe == BSDF_GLASS ? Rng_next(rng) : 0.0f;
    float3 dir = st->dir, org;
    st->throughput *= Surface_specular(sp, m, lobe, base, u, &dir, &org, &refracted);
    if (st->bounces == 0) st->first_pass = refracted ? PASS_TRANSMISSION : PASS_GLOSSY;
    Image_continue(st, org, dir);
    st->caustic = st->diffuse > 0;
    st->bounces++;
    return true;
}

/* Follow the camera path through image position (px, py) (pixel (wx, wy)
 * of the window) until it ends; writes what it brings into `path`. */
inline void Image_path(const SceneView *sc, const Camera *cam, const ImageJob *job, IMAGE_GI_PARAMS,
                       int wx, int wy, float px, float py, Rng *rng, ImagePath *path) {
    ImageState st = {.throughput = (float3)(1.0f), .first_pass = PASS_DIFFUSE};
    Camera_ray(cam, px, py, &st.org, &st.dir, &st.tmin, &st.tmax);
    for (int p = 0; p < IMAGE_SLOTS; ++p) path->light[p] = (float3)(0.0f);
    path->alpha = 1.0f;
    path->albedo = path->feature_normal = path->normal = (float3)(0.0f);
    path->depth = 1e10f;
    while (true) {
        Hit hit;
        bool found = KdTree_intersect(&sc->tree, st.org, st.dir, st.tmin, st.tmax, &hit);
        /* emitters hit by the path count unless a shadow ray already
         * sampled them (next-event estimation at a diffuse event): before
         * any diffuse event, or after specular events that followed one */
        bool unsampled = st.diffuse == 0 || st.caustic;
        /* lights are see-through emitters: add those before the surface. As
         * in Cycles by default, only scattered rays see them, not the camera */
        if (st.bounces > 0 && unsampled && sc->light_count > 0) {
            float3 seen = Image_lights_seen(sc, st.org, st.dir, found ? hit.t : st.tmax, !found);
            Image_add(path->light, st.throughput * seen, st.first_pass, st.bounces, false, st.caustic);
        }
        if (!found) {
            if (st.bounces == 0 && st.passes == 0 && sc->world.w > 0.0f) path->alpha = 0.0f;
            else if (unsampled)
                Image_add(path->light, st.throughput * sc->world.xyz, st.first_pass, st.bounces, true, st.caustic);
            if (!st.features_done) path->albedo = st.throughput;
            return;
        }
        SurfacePoint sp = Surface_at(sc, st.dir, &hit);
        Material m = sc->materials[sp.material];
        float3 base = Surface_base(sc, &m, sp.uv);
        /* stochastic alpha: pass straight through */
        if (m.base_color.w < 1.0f && Rng_next(rng) >= m.base_color.w && st.passes < IMAGE_MAX_PASSTHROUGH) {
            st.passes++;
            Image_continue(&st, sp.p - sp.eps * sp.ng, st.dir);
            continue;
        }
        if (st.bounces == 0) {
            path->depth = Camera_depth(cam, sp.p);
            path->normal = sp.ns;
        }
        if (unsampled) Image_add(path->light, st.throughput * m.emission.xyz, st.first_pass, st.bounces, false, st.caustic);
        int lobe = Bsdf_pick(&m, Rng_next(rng));
        bool goes_on = lobe == BSDF_DIFFUSE
            ? Image_diffuse_event(sc, cam, job, gi_pos, gi_nrm, gi_indirect, gi_caustic, wx, wy, &sp, base, rng, &st,
                                  path)
            : Image_specular_event(job, &sp, &m, lobe, base, rng, &st);
        if (!goes_on) return;
    }
}

/* Add a path's light to its pixel's sums. The clamp scales every pass of
 * the path alike, so they still add up to Combined; a non-finite path is
 * dropped. */
inline void Image_accumulate(const ImagePath *path, float clamp_value, float3 *pixel_light) {
    float3 radiance = (float3)(0.0f);
    for (int p = 0; p < IMAGE_SUMMED; ++p) radiance += path->light[p];
    if (!(isfinite(radiance.x) && isfinite(radiance.y) && isfinite(radiance.z))) return;
    float3 scale = (float3)(1.0f);
    if (clamp_value > 0.0f) scale = fmin(radiance, (float3)(clamp_value)) / fmax(radiance, (float3)(1e-30f));
    for (int p = 0; p < IMAGE_SLOTS; ++p) pixel_light[p] += path->light[p] * scale;
}

/* The pixel filter's offset from the pixel centre along one axis, for u in
 * [0, 1): its inverse CDF, tabulated on the host (shading/pixel_filter.py). */
inline float Image_filter_offset(const __global float *table, float u) {
    float x = clamp(u, 0.0f, 1.0f) * (float)(FILTER_TABLE_SIZE - 1);
    int i = min((int)x, FILTER_TABLE_SIZE - 2);
    return mix(table[i], table[i + 1], x - (float)i);
}

/* Pixel order: launches take the window's pixels in strips of IMAGE_STRIP
 * rows, column by column within a strip, so that a work-group's work-items
 * cover a block of the image rather than a line (IMAGE_STRIP 1: rows). The
 * g-th pixel of the window in that order, as (x, y). */
#ifndef IMAGE_STRIP
#define IMAGE_STRIP 8
#endif
inline int2 Image_pixel_of(int g, int w, int h) {
    int strip = g / (w * IMAGE_STRIP);
    int rows = min(IMAGE_STRIP, h - strip * IMAGE_STRIP);
    int k = g - strip * w * IMAGE_STRIP;
    return (int2)(k / rows, strip * IMAGE_STRIP + k % rows);
}

/* One work item per pixel of the launch (job.window: width, height, pixels
 * in this launch, first pixel of the launch; job.origin: the window's
 * lower-left pixel), all its samples. Light passes are stored pass after
 * pass, each the size of the window. */
__kernel void Image_pixels(SCENE_PARAMS, const ImageJob job, const __global float *pixel_filter, IMAGE_GI_PARAMS,
                           __global float4 *out_combined,
                           __global float *out_depth, __global float4 *out_normal, __global float4 *out_light,
                           __global float4 *out_albedo, __global float4 *out_feature_normal) {
    int i = get_global_id(0);
    int g = job.window.w + i; /* index in the render window, in pixel order */
    int window_pixels = job.window.x * job.window.y;
    if (i >= job.window.z || g >= window_pixels) return;
    SceneView sc = SCENE_MAKE();
    Camera cam = *sc.camera;
    int2 wp = Image_pixel_of(g, job.window.x, job.window.y);
    int wx = wp.x, wy = wp.y;
    int o = wy * job.window.x + wx; /* where the pixel's outputs go (rows) */
    int px = job.origin.x + wx, py = job.origin.y + wy;

    float3 pixel_light[IMAGE_SLOTS];
    for (int p = 0; p < IMAGE_SLOTS; ++p) pixel_light[p] = (float3)(0.0f);
    float alpha_sum = 0.0f;
    float3 albedo_sum = (float3)(0.0f), feature_normal_sum = (float3)(0.0f);
    float depth = 1e10f;
    float3 normal = (float3)(0.0f);
    /* anti-aliasing: the pixel's samples follow the R2 sequence from a
     * random offset, so they cover the unit square evenly, and the pixel
     * filter's inverse CDF takes them around the pixel's centre */
    uint pixel_id = (uint)(py * cam.width + px);
    uint aa_x = Rng_hash(pixel_id ^ Rng_hash(job.seed ^ 0xa511e9b3U));
    uint aa_y = Rng_hash(aa_x);
    for (int s = 0; s < job.samples; ++s) {
        uint number = (uint)(job.sample_start + s); /* the path's number among all the pixel's passes */
        Rng rng = Rng_make(pixel_id, number, job.seed);
        float2 aa = Rng_r2(number, aa_x, aa_y);
        ImagePath path;
        float sx = (float)px + 0.5f + Image_filter_offset(pixel_filter, aa.x);
        float sy = (float)py + 0.5f + Image_filter_offset(pixel_filter, aa.y);
        Image_path(&sc, &cam, &job, gi_pos, gi_nrm, gi_indirect, gi_caustic, wx, wy, sx, sy, &rng, &path);
        Image_accumulate(&path, job.clamp, pixel_light);
        alpha_sum += path.alpha;
        albedo_sum += path.albedo;
        feature_normal_sum += path.feature_normal;
        if (s == 0) {
            depth = path.depth;
            normal = path.normal;
        }
    }
    float inv = 1.0f / (float)job.samples;
    float3 total = (float3)(0.0f);
    for (int p = 0; p < IMAGE_SUMMED; ++p) total += pixel_light[p];
    out_combined[o] = (float4)(total * inv, alpha_sum * inv);
    out_depth[o] = depth;
    out_normal[o] = (float4)(normal, 0.0f);
#ifdef IMAGE_LIGHT_PASSES
    for (int p = 0; p < PASS_COUNT; ++p) out_light[p * window_pixels + o] = (float4)(pixel_light[p] * inv, 0.0f);
#endif
    if (job.outputs & OUTPUT_DENOISING) {
        out_albedo[o] = (float4)(albedo_sum * inv, 0.0f);
        out_feature_normal[o] = (float4)(feature_normal_sum * inv, 0.0f);
    }
}
