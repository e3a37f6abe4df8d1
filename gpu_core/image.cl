/* The image kernel (also the reference path tracer): camera paths through
 * the scene's BSDFs (shading/bsdf.h). At every event with a smooth lobe
 * (diffuse or glossy) shadow rays sample the lights and the BSDF samples
 * the path's next direction, the two weighted by multiple importance
 * sampling (power heuristic), so neither small lights on rough surfaces
 * nor large lights on sharp ones are noisy; singular lobes (mirror, smooth
 * glass) are followed as they are. In GI mode (IMAGE_GI) the diffuse lobe
 * of the first smooth event reads the cached indirect light and caustics
 * instead of tracing diffuse bounces; its glossy lobes go on, and where
 * such a path meets a diffuse surface that surface's light comes from the
 * illumination cut (IMAGE_GLOSSY_CUT, gi/cut_lookup.h): the photons'
 * irradiance there, direct light included. The light is split into
 * Blender's light passes (PASS_*, device/constants.py). */
#include "device/launch.h"
#include "device/rng.h"
#include "device/sampling.h"
#include "shading/camera.h"
#include "shading/surface.h"
#ifdef IMAGE_GLOSSY_CUT
#include "gi/cut_lookup.h"
#endif

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
 * normal, indirect and caustic irradiance; with glossy surfaces, the cut. */
#ifdef IMAGE_GLOSSY_CUT
#define IMAGE_GI_PARAMS                                                      \
    const __global float4 *gi_pos, const __global float4 *gi_nrm,           \
        const __global float4 *gi_indirect, const __global float4 *gi_caustic, CUT_PARAMS
#else
#define IMAGE_GI_PARAMS                                                      \
    const __global float4 *gi_pos, const __global float4 *gi_nrm,           \
        const __global float4 *gi_indirect, const __global float4 *gi_caustic
#endif

typedef struct {
    const __global float4 *pos, *nrm, *indirect, *caustic;
#ifdef IMAGE_GLOSSY_CUT
    Cut cut;
#endif
} ImageGi;

/* Fraction of light passing along a shadow ray, per channel: 0 when an
 * opaque surface blocks it; with see-through materials in the scene (alpha,
 * Transparent shaders), the product of their transmittances. */
inline float3 Image_visibility(const SceneView *sc, float3 org, float3 dir, float tmax) {
#ifdef SCENE_HAS_ALPHA
    float3 vis = (float3)(1.0f);
    float tmin = 0.0f;
    for (int i = 0; i < IMAGE_MAX_PASSTHROUGH; ++i) {
        Hit hit;
        if (!KdTree_intersect(&sc->tree, org, dir, tmin, tmax, &hit)) return vis;
        vis *= Surface_transmittance(sc, hit.tri, Surface_uv(sc, &hit));
        if (!(vis.x > 0.0f || vis.y > 0.0f || vis.z > 0.0f)) return (float3)(0.0f);
        tmin = hit.t + Ray_offset(fmax(hit.t, Ray_magnitude(org)));
    }
    return (float3)(0.0f);
#else
    return (float3)(KdTree_occluded(&sc->tree, org, dir, 0.0f, tmax) ? 0.0f : 1.0f);
#endif
}

/* The power heuristic's weight of a BSDF-sampled direction of pdf p_bsdf
 * that a light sampler would find with pdf p_light (1 where the BSDF
 * sampled a singular lobe or the light cannot be sampled). */
inline float Image_mis(float p_bsdf, float p_light) {
    if (!(p_bsdf > 0.0f) || !(p_light > 0.0f)) return 1.0f;
    float a = p_bsdf * p_bsdf, b = p_light * p_light;
    return isfinite(a + b) ? a / (a + b) : (p_bsdf > p_light ? 1.0f : 0.0f);
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

/* Shadow rays a light row gets per light-sample round, on average: one
 * each with few lights, else its pick probability. */
inline float Image_light_rate(const SceneView *sc, int i) {
    if (sc->light_count <= IMAGE_ALL_LIGHTS) return 1.0f;
    return sc->lights[i].pick - (i > 0 ? sc->lights[i - 1].pick : 0.0f);
}

/* Light of sample ls, taken from the shadow ray's origin org, through the
 * BSDF f and weighted against BSDF sampling (`rate`: the light's shadow
 * rays per round x rounds; `scale` on its value). Adds the diffuse and
 * glossy parts of f's response. */
inline void Image_shadow_ray(const SceneView *sc, const Bsdf *f, float3 org, const LightSample *ls, float scale,
                             float rate, float3 *diffuse, float3 *glossy) {
    if (!(ls->value.x > 0.0f || ls->value.y > 0.0f || ls->value.z > 0.0f) || !(ls->dist > 0.0f)) return;
    float3 d;
    float pdf;
    float3 g = Bsdf_eval(f, Bsdf_to_local(f, ls->dir), &d, &pdf);
    if (!(d.x > 0.0f || d.y > 0.0f || d.z > 0.0f || g.x > 0.0f || g.y > 0.0f || g.z > 0.0f)) return;
    float w = ls->pdf > 0.0f ? Image_mis(ls->pdf * rate, pdf) : 1.0f;
    float3 arriving = ls->value * (scale * w) * Image_visibility(sc, org, ls->dir, ls->dist);
    *diffuse += d * arriving;
    *glossy += g * arriving;
}

/* One sample of light l at a scattering point (u: its random numbers).
 * The light is sampled from the shadow ray's origin, just above the
 * surface (so the ray ends at the sampled point), or just below it where
 * the light lies behind (transmission through rough glass). */
inline void Image_light_sample(const SceneView *sc, const Bsdf *f, const SurfacePoint *sp, const Light *l, float3 u,
                               float scale, float rate, float3 *diffuse, float3 *glossy) {
    float3 org = sp->p + sp->eps * sp->ng;
    LightSample ls = Light_sample(l, &sc->em, org, u.x, u.y, u.z);
    if (dot(ls.dir, sp->ng) < 0.0f) {
        if (!(f->w_glass > 0.0f)) return;
        org = sp->p - sp->eps * sp->ng;
        ls = Light_sample(l, &sc->em, org, u.x, u.y, u.z);
        if (dot(ls.dir, sp->ng) >= 0.0f) return;
    }
    Image_shadow_ray(sc, f, org, &ls, scale, rate, diffuse, glossy);
}

/* The numbers of a path's first smooth scattering event: the pixel's paths
 * (and their light-sample rounds) draw each pair of them from one scrambled
 * Sobol sequence of the pixel (Rng_sobol2), so that they cover a light's
 * area and a lobe's directions evenly, as the R2 anti-aliasing covers the
 * pixel; later events draw from the path's stream. */
typedef struct {
    uint index; /* the path's number among the pixel's paths */
    uint seed;  /* the pixel's */
    bool on;    /* false past the first smooth event */
} ImageStrata;

/* The sequences of a pixel: one per light row (up to IMAGE_ALL_LIGHTS), one
 * for a light picked among many, one for the world, one for the BSDF. */
#define IMAGE_PAIR_PICKED 0x40U
#define IMAGE_PAIR_WORLD 0x41U
#define IMAGE_PAIR_BSDF 0x42U

/* Two numbers of the path's stream. */
inline float2 Image_random2(Rng *rng) {
    float a = Rng_next(rng);
    return (float2)(a, Rng_next(rng));
}

/* Two numbers for pair `pair` in round k of `rounds` (light samples). */
inline float2 Image_pair(const ImageStrata *strata, uint pair, int k, int rounds, Rng *rng) {
    if (!strata->on) return Image_random2(rng);
    return Rng_sobol2(strata->index * (uint)rounds + (uint)k, strata->seed ^ Rng_hash(pair));
}

/* Direct light at a scattering point, world included: light_samples
 * rounds, averaged. With up to IMAGE_ALL_LIGHTS lights a round sends a
 * shadow ray to every light (the least noise for the rays); with more,
 * one ray to one light picked by power, so a frame's cost does not grow
 * with the number of lights. Writes the diffuse and glossy parts. */
inline void Image_direct(const SceneView *sc, const Bsdf *f, const SurfacePoint *sp, int light_samples,
                         const ImageStrata *strata, Rng *rng, float3 *diffuse, float3 *glossy) {
    *diffuse = *glossy = (float3)(0.0f);
    bool has_world = Scene_has_world(sc);
    float rounds = (float)light_samples;
    for (int k = 0; k < light_samples; ++k) {
        if (sc->light_count <= IMAGE_ALL_LIGHTS) {
            for (int i = 0; i < sc->light_count; ++i) {
                Light l = sc->lights[i];
                float2 v = Image_pair(strata, (uint)i, k, light_samples, rng);
                float3 u = (float3)(Rng_next(rng), v.x, v.y);
                Image_light_sample(sc, f, sp, &l, u, 1.0f, rounds, diffuse, glossy);
            }
        } else {
            float p;
            Light l = sc->lights[Image_pick_light(sc, Rng_next(rng), &p)];
            float2 v = Image_pair(strata, IMAGE_PAIR_PICKED, k, light_samples, rng);
            float3 u = (float3)(Rng_next(rng), v.x, v.y);
            if (p > 0.0f) Image_light_sample(sc, f, sp, &l, u, 1.0f / p, rounds * p, diffuse, glossy);
        }
        if (has_world) {
            float2 v = Image_pair(strata, IMAGE_PAIR_WORLD, k, light_samples, rng);
            LightSample ls = Light_sample_world(sc->world.xyz, sp->ns, v.x, v.y);
            if (dot(ls.dir, sp->ng) >= 0.0f)
                Image_shadow_ray(sc, f, sp->p + sp->eps * sp->ng, &ls, 1.0f, rounds, diffuse, glossy);
        }
    }
    *diffuse /= rounds;
    *glossy /= rounds;
}

/* Light passes, with Cycles' meaning: a path's light goes to the pass of
 * the lobe its first scattering event took (diffuse, glossy = reflection
 * off metal, glass or the specular layer, transmission = refraction),
 * "direct" when it arrived after that one event and "indirect" after more;
 * light seen before any scattering is Emission (surfaces) or Environment
 * (the world). Passes before PASS_SUMMED add up to Combined. Caustics
 * repeats the part of them that reached a smooth surface through singular
 * events (light no shadow ray can sample). Add light c, which arrived
 * after `events` scattering events, to its pass. */
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
inline bool Image_gi_lookup(const ImageGi *gi, int sub, int w, int h, int wx, int wy, float3 p, float3 n,
                            float3 *indirect, float3 *caustic) {
    int best = -1;
    float best_d2 = INFINITY;
    for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
            int x = wx + dx, y = wy + dy;
            if (x < 0 || y < 0 || x >= w || y >= h) continue;
            int first = (y * w + x) * sub * sub;
            for (int k = first; k < first + sub * sub; ++k) {
                float4 q = gi->pos[k];
                if (q.w <= 0.0f || dot(gi->nrm[k].xyz, n) < IMAGE_GI_MIN_COS) continue;
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
    *indirect = gi->indirect[best].xyz;
    *caustic = gi->caustic[best].xyz;
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
    float3 albedo;            /* denoising albedo: at the first smooth event, or the world */
    float3 feature_normal;    /* denoising normal (camera space), at the first smooth event */
    float depth;              /* of the first surface hit (1e10 when none) */
    float3 normal;            /* its shading normal */
} ImagePath;

/* Where a camera path is: its ray, what it carries, what it went through. */
typedef struct {
    float3 org, dir;
    float tmin, tmax;
    float3 throughput;
    int bounces, smooth, diffuse, passes; /* events: all, smooth ones, diffuse ones; alpha pass-throughs */
    int first_pass;      /* the pass of its first scattering event */
    bool caustic;        /* a singular event since the last smooth one (and there was one) */
    bool features_done;  /* the denoising features are taken */
    float pdf;           /* pdf of the ray's direction (0: singular, or from the camera) */
    float3 prev_n;       /* shading normal where it left (the world sampler's pdf) */
    ImageStrata strata;  /* numbers of the first smooth event */
} ImageState;

/* The path leaves from p along dir, a new segment. */
inline void Image_continue(ImageState *st, float3 p, float3 dir) {
    st->org = p;
    st->dir = dir;
    st->tmin = 0.0f;
    st->tmax = RAY_FAR;
}

/* Radiance of the lights a ray passes before tmax (an escaping ray also
 * sees sun disks), each weighted against its light sampler. */
inline float3 Image_lights_seen(const SceneView *sc, const ImageState *st, int light_samples, float tmax,
                                bool escaped) {
    float3 sum = (float3)(0.0f);
    for (int i = 0; i < sc->light_count; ++i) {
        Light l = sc->lights[i];
        float rate = Image_light_rate(sc, i) * (float)light_samples, pdf;
        float3 seen = Light_seen(&l, st->org, st->dir, st->tmin, tmax, &pdf);
        sum += seen * Image_mis(st->pdf, pdf * rate);
        if (escaped) {
            seen = Light_sun_seen(&l, st->dir, &pdf);
            sum += seen * Image_mis(st->pdf, pdf * rate);
        }
    }
    return sum;
}

/* Weight of an emissive triangle's light reached by the path's last ray
 * (its hit at distance t), against the mesh light's sampler (the last
 * light row, scene/tables.py). */
inline float Image_mesh_mis(const SceneView *sc, const ImageState *st, int light_samples, int tri, float t) {
    int i = sc->light_count - 1;
    if (!(st->pdf > 0.0f) || i < 0 || sc->lights[i].kind != LIGHT_MESH) return 1.0f;
    float rate = Image_light_rate(sc, i) * (float)light_samples;
    return Image_mis(st->pdf, rate * Light_mesh_pdf(&sc->em, tri, st->dir, t));
}

/* The lobes the path may sample next: diffuse ones while diffuse bounces
 * are left, the others while specular bounces are; in GI mode never the
 * diffuse lobe (the cache and the cut stand for its light). */
inline int Image_sample_lobes(const ImageJob *job, const ImageState *st) {
    int lobes = 0;
    if (st->bounces >= job->max_bounces + job->max_diffuse) return 0;
    if (st->diffuse < job->max_diffuse) lobes |= BSDF_SAMPLE_DIFFUSE;
    if (st->bounces - st->diffuse < job->max_bounces) lobes |= BSDF_SAMPLE_GLOSSY;
    return lobes;
}

/* A scattering event at sp: emission was added by the caller; here direct
 * light (smooth lobes), in GI mode the cache (first smooth event) or the
 * cut (later ones) for the diffuse lobe, then the next direction. Returns
 * whether the path goes on. */
inline bool Image_scatter(const SceneView *sc, const Camera *cam, const ImageJob *job, const ImageGi *gi, int wx,
                          int wy, const SurfacePoint *sp, const Material *m, float3 base, Rng *rng, ImageState *st,
                          ImagePath *path) {
    Bsdf f = Surface_bsdf(sp, m, base, st->dir, Image_sample_lobes(job, st));
    bool smooth = Bsdf_has_smooth(&f);
    if (smooth && !st->features_done) {
        /* the lobes' colours, as the denoiser's albedo guide */
        float3 colours = f.diffuse + f.w_metal * f.metal_f0 + f.w_specular * f.spec_f0 + f.w_glass * f.glass_ttint;
        path->albedo = st->throughput * fmin(colours, (float3)(1.0f));
        path->feature_normal = Image_to_camera(cam, sp->ns);
        st->features_done = true;
    }
#ifdef IMAGE_GI
    bool diffuse_light = f.diffuse.x > 0.0f || f.diffuse.y > 0.0f || f.diffuse.z > 0.0f;
    if (st->smooth == 0 && diffuse_light) {
        /* GI mode: indirect light and caustics from the cache at the first smooth event */
        float3 e_indirect, e_caustic;
        if (Image_gi_lookup(gi, job->gi_subpixels, job->window.x, job->window.y, wx, wy, sp->p, sp->ns, &e_indirect,
                            &e_caustic)) {
            float3 k = st->throughput * f.diffuse * (1.0f / PI_F);
            int pass = st->bounces == 0 ? PASS_DIFFUSE : st->first_pass;
            Image_add(path->light, k * e_indirect, pass, st->bounces + 2, false, false);
            Image_add(path->light, k * e_caustic, pass, st->bounces + 2, false, true);
        }
    }
#ifdef IMAGE_GLOSSY_CUT
    if (st->smooth > 0 && diffuse_light) {
        /* after a glossy bounce: the diffuse lobe's light, direct included, from the cut */
        float3 e = CutLookup_light(&gi->cut, sp->p, sp->ns);
        Image_add(path->light, st->throughput * f.diffuse * (1.0f / PI_F) * e, st->first_pass, st->bounces + 2, false,
                  false);
        f.diffuse = (float3)(0.0f);
    }
#endif
#endif
    if (smooth) {
        float3 d, g;
        Image_direct(sc, &f, sp, job->light_samples, &st->strata, rng, &d, &g);
        if (st->bounces == 0) {
            Image_add(path->light, st->throughput * d, PASS_DIFFUSE, 1, false, false);
            Image_add(path->light, st->throughput * g, PASS_GLOSSY, 1, false, false);
        } else {
            Image_add(path->light, st->throughput * (d + g), st->first_pass, st->bounces + 1, false, false);
        }
    }
    /* the next direction */
    float u_lobe = Rng_next(rng);
    float2 u = smooth ? Image_pair(&st->strata, IMAGE_PAIR_BSDF, 0, 1, rng) : Image_random2(rng);
    float u3 = Rng_next(rng);
    if (smooth) st->strata.on = false;
    float3 wi, weight;
    float pdf;
    int label = Bsdf_sample(&f, u_lobe, u.x, u.y, u3, &wi, &weight, &pdf);
    if (label == 0) return false;
    float3 dir = Bsdf_to_world(&f, wi);
    if (st->bounces == 0)
        st->first_pass = (label & BSDF_LABEL_TRANSMIT) ? PASS_TRANSMISSION
                         : (label & BSDF_LABEL_DIFFUSE) ? PASS_DIFFUSE : PASS_GLOSSY;
    st->throughput *= weight;
    bool singular = (label & BSDF_LABEL_SINGULAR) != 0;
    st->caustic = singular ? (st->caustic || st->smooth > 0) : false;
    if (!singular) st->smooth++;
    if (label & BSDF_LABEL_DIFFUSE) st->diffuse++;
    st->bounces++;
    st->pdf = pdf;
    st->prev_n = sp->ns;
    /* Russian roulette after two smooth bounces keeps the estimate unbiased */
    if (!singular && st->smooth > 2) {
        float q = fmin(fmax(fmax(st->throughput.x, st->throughput.y), st->throughput.z), 0.95f);
        if (!(Rng_next(rng) < q)) return false;
        st->throughput /= q;
    }
    Image_continue(st, Surface_leave(sp, dir), dir);
    return true;
}

/* Follow the camera path through image position (px, py) (pixel (wx, wy)
 * of the window) until it ends; writes what it brings into `path`. */
inline void Image_path(const SceneView *sc, const Camera *cam, const ImageJob *job, const ImageGi *gi, int wx, int wy,
                       float px, float py, ImageStrata strata, Rng *rng, ImagePath *path) {
    ImageState st = {.throughput = (float3)(1.0f), .first_pass = PASS_DIFFUSE, .strata = strata};
    Camera_ray(cam, px, py, &st.org, &st.dir, &st.tmin, &st.tmax);
    for (int p = 0; p < IMAGE_SLOTS; ++p) path->light[p] = (float3)(0.0f);
    path->alpha = 1.0f;
    path->albedo = path->feature_normal = path->normal = (float3)(0.0f);
    path->depth = 1e10f;
    while (true) {
        Hit hit;
        bool found = KdTree_intersect(&sc->tree, st.org, st.dir, st.tmin, st.tmax, &hit);
        /* lights are see-through emitters: add those before the surface. As
         * in Cycles by default, only scattered rays see them, not the camera */
        if (st.bounces > 0 && sc->light_count > 0) {
            float3 seen = Image_lights_seen(sc, &st, job->light_samples, found ? hit.t : st.tmax, !found);
            Image_add(path->light, st.throughput * seen, st.first_pass, st.bounces, false, st.caustic);
        }
        if (!found) {
            if (st.bounces == 0 && st.passes == 0 && sc->world.w > 0.0f) {
                path->alpha = 0.0f;
            } else {
                float w = Image_mis(st.pdf, fmax(dot(st.prev_n, st.dir), 0.0f) / PI_F * (float)job->light_samples);
                Image_add(path->light, st.throughput * sc->world.xyz * (st.bounces > 0 ? w : 1.0f), st.first_pass,
                          st.bounces, true, st.caustic);
            }
            if (!st.features_done) path->albedo = st.throughput;
            return;
        }
        SurfacePoint sp = Surface_at(sc, st.dir, &hit);
        Material m = Surface_material(sc, sp.tri, sp.uv, SURFACE_MIX_U(rng));
        float3 base = Surface_textured(sc, &m, &sp);
        /* stochastic alpha: pass straight through */
        if (m.base_color.w < 1.0f && Rng_next(rng) >= m.base_color.w && st.passes < IMAGE_MAX_PASSTHROUGH) {
            st.passes++;
            st.throughput *= m.mix_scale * Surface_pass_tint(&m);
            /* the segment goes on from the same origin, so the lights and
             * emitters it meets are weighed from the point that scattered it */
            st.tmin = hit.t + Ray_offset(fmax(hit.t, Ray_magnitude(st.org)));
            continue;
        }
        if (st.bounces == 0) {
            path->depth = Camera_depth(cam, sp.p);
            path->normal = sp.ns;
        }
        if (m.emission.x > 0.0f || m.emission.y > 0.0f || m.emission.z > 0.0f) {
            float w = st.bounces > 0 ? Image_mesh_mis(sc, &st, job->light_samples, hit.tri, hit.t) : 1.0f;
            Image_add(path->light, st.throughput * m.emission.xyz * w, st.first_pass, st.bounces, false, st.caustic);
        }
        if (!Image_scatter(sc, cam, job, gi, wx, wy, &sp, &m, base, rng, &st, path)) return;
    }
}

/* Add a path's light to its pixel's sums; returns what it added to
 * Combined. The clamp scales every pass of the path alike, so they still
 * add up to Combined; a non-finite path is dropped. */
inline float3 Image_accumulate(const ImagePath *path, float clamp_value, float3 *pixel_light) {
    float3 radiance = (float3)(0.0f);
    for (int p = 0; p < IMAGE_SUMMED; ++p) radiance += path->light[p];
    if (!(isfinite(radiance.x) && isfinite(radiance.y) && isfinite(radiance.z))) return (float3)(0.0f);
    float3 scale = (float3)(1.0f);
    if (clamp_value > 0.0f) scale = fmin(radiance, (float3)(clamp_value)) / fmax(radiance, (float3)(1e-30f));
    for (int p = 0; p < IMAGE_SLOTS; ++p) pixel_light[p] += path->light[p] * scale;
    return radiance * scale;
}

/* The mean of `count` new samples (their sum) merged into the mean of
 * `done` earlier ones (old, not read when there are none). */
inline float4 Image_merge(float4 old, float4 sum, int done, int count) {
    float inv = 1.0f / (float)(done + count);
    return done > 0 ? old * ((float)done * inv) + sum * inv : sum * inv;
}

/* Even numbers in [0, n): the even-numbered samples among a pixel's first n. */
inline int Image_evens(int n) { return (n + 1) / 2; }

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
 * lower-left pixel), job.samples samples each. Light passes are stored
 * pass after pass, each the size of the window. With adaptive sampling
 * (OUTPUT_ADAPTIVE) a launch is one round: only pixels flagged in
 * `active` take samples, up to job.sample_limit in all, and their means
 * are merged with those of the rounds before; `adaptive` holds per pixel
 * the mean of its even-numbered samples' Combined (xyz) and its sample
 * count (w), from which Image_adaptive_active judges its noise. */
__kernel void Image_pixels(SCENE_PARAMS, const ImageJob job, const __global float *pixel_filter, IMAGE_GI_PARAMS,
                           __global float4 *out_combined,
                           __global float *out_depth, __global float4 *out_normal, __global float4 *out_light,
                           __global float4 *out_albedo, __global float4 *out_feature_normal,
                           __global float4 *adaptive, const __global int *active) {
    int i = Launch_global_id();
    int g = job.window.w + i; /* index in the render window, in pixel order */
    int window_pixels = job.window.x * job.window.y;
    if (i >= job.window.z || g >= window_pixels) return;
    int2 wp = Image_pixel_of(g, job.window.x, job.window.y);
    int wx = wp.x, wy = wp.y;
    int o = wy * job.window.x + wx; /* where the pixel's outputs go (rows) */
    /* samples the pixel has from earlier rounds, and those it takes now */
    int done = 0, count = job.samples;
    if (job.outputs & OUTPUT_ADAPTIVE) {
        if (!active[o]) return;
        done = (int)adaptive[o].w;
        count = min(count, job.sample_limit - done);
        if (count <= 0) return;
    }
    SceneView sc = SCENE_MAKE();
    Camera cam = *sc.camera;
#ifdef IMAGE_GLOSSY_CUT
    ImageGi gi = {gi_pos, gi_nrm, gi_indirect, gi_caustic, CUT_MAKE()};
#else
    ImageGi gi = {gi_pos, gi_nrm, gi_indirect, gi_caustic};
#endif
    int px = job.origin.x + wx, py = job.origin.y + wy;

    float3 pixel_light[IMAGE_SLOTS];
    for (int p = 0; p < IMAGE_SLOTS; ++p) pixel_light[p] = (float3)(0.0f);
    float alpha_sum = 0.0f;
    float3 albedo_sum = (float3)(0.0f), feature_normal_sum = (float3)(0.0f), even_sum = (float3)(0.0f);
    float depth = 1e10f;
    float3 normal = (float3)(0.0f);
    /* anti-aliasing: the pixel's samples follow the R2 sequence from a
     * random offset, so they cover the unit square evenly, and the pixel
     * filter's inverse CDF takes them around the pixel's centre */
    uint pixel_id = (uint)(py * cam.width + px);
    uint aa_x = Rng_hash(pixel_id ^ Rng_hash(job.seed ^ 0xa511e9b3U));
    uint aa_y = Rng_hash(aa_x);
    uint strata_seed = Rng_hash(aa_y ^ 0x68e31da4U);
    for (int s = done; s < done + count; ++s) {
        uint number = (uint)(job.sample_start + s); /* the path's number among all the pixel's passes */
        Rng rng = Rng_make(pixel_id, number, job.seed);
        float2 aa = Rng_r2(number, aa_x, aa_y);
        ImagePath path;
        float sx = (float)px + 0.5f + Image_filter_offset(pixel_filter, aa.x);
        float sy = (float)py + 0.5f + Image_filter_offset(pixel_filter, aa.y);
        ImageStrata strata = {number, strata_seed, true};
        Image_path(&sc, &cam, &job, &gi, wx, wy, sx, sy, strata, &rng, &path);
        float3 added = Image_accumulate(&path, job.clamp, pixel_light);
        if ((s & 1) == 0) even_sum += added;
        alpha_sum += path.alpha;
        albedo_sum += path.albedo;
        feature_normal_sum += path.feature_normal;
        if (s == 0) {
            depth = path.depth;
            normal = path.normal;
        }
    }
    float3 total = (float3)(0.0f);
    for (int p = 0; p < IMAGE_SUMMED; ++p) total += pixel_light[p];
    out_combined[o] = Image_merge(done > 0 ? out_combined[o] : (float4)(0.0f), (float4)(total, alpha_sum), done, count);
    if (done == 0) {
        out_depth[o] = depth;
        out_normal[o] = (float4)(normal, 0.0f);
    }
#ifdef IMAGE_LIGHT_PASSES
    for (int p = 0; p < PASS_COUNT; ++p) {
        int at = p * window_pixels + o;
        out_light[at] = Image_merge(done > 0 ? out_light[at] : (float4)(0.0f), (float4)(pixel_light[p], 0.0f), done,
                                    count);
    }
#endif
    if (job.outputs & OUTPUT_DENOISING) {
        out_albedo[o] = Image_merge(done > 0 ? out_albedo[o] : (float4)(0.0f), (float4)(albedo_sum, 0.0f), done, count);
        out_feature_normal[o] = Image_merge(done > 0 ? out_feature_normal[o] : (float4)(0.0f),
                                            (float4)(feature_normal_sum, 0.0f), done, count);
    }
    if (job.outputs & OUTPUT_ADAPTIVE) {
        int evens_before = Image_evens(done), evens = Image_evens(done + count) - evens_before;
        float4 even = evens > 0 ? Image_merge(adaptive[o], (float4)(even_sum, 0.0f), evens_before, evens) : adaptive[o];
        adaptive[o] = (float4)(even.xyz, (float)(done + count));
    }
}

/* A pixel's noise as Cycles' adaptive sampling judges it [Dammertz et al.
 * 2010, section 2.1]: the difference between the mean of all its samples
 * and that of its even-numbered ones, relative to the square root of its
 * brightness (to the brightness itself above 1, where it is overexposed). */
inline float Image_noise(float4 combined, float4 even) {
    float3 d = fabs(combined.xyz - even.xyz);
    float intensity = combined.x + combined.y + combined.z;
    float normalise = intensity < 1.0f ? sqrt(fmax(intensity, 0.0f)) : intensity;
    return (d.x + d.y + d.z) / (0.0001f + normalise);
}

/* The noise of each pixel that took samples in the round just done
 * (`active`): a pixel's noise changes only when it takes samples. */
__kernel void Image_noise_of(const ImageJob job, const __global float4 *combined, const __global float4 *adaptive,
                             const __global int *active, __global float *noise) {
    int o = Launch_global_id();
    if (o >= job.window.x * job.window.y || !active[o]) return;
    noise[o] = Image_noise(combined[o], adaptive[o]);
}

/* The pixels of the window that take the next round: those below
 * job.sample_limit samples whose own noise, or a neighbour's (3 x 3), is
 * at least `threshold`, so that noisy regions keep their rims sampled;
 * counter[0] counts them. One work item per pixel of the window, in rows. */
__kernel void Image_adaptive_active(const ImageJob job, const __global float *noise,
                                    const __global float4 *adaptive, const float threshold, __global int *active,
                                    volatile __global int *counter) {
    int o = Launch_global_id();
    int w = job.window.x, h = job.window.y;
    if (o >= w * h) return;
    int x = o % w, y = o / w;
    bool noisy = false;
    for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
            int nx = x + dx, ny = y + dy;
            if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
            noisy = noisy || !(noise[ny * w + nx] < threshold);
        }
    }
    bool take = noisy && (int)adaptive[o].w < job.sample_limit;
    active[o] = take ? 1 : 0;
    if (take) atomic_inc(counter);
}
