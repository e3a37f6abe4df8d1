/* The surface at a ray hit: position, normals facing the ray, UV, material,
 * and the offset for rays leaving it. Shared by every kernel that shades. */
#ifndef GPUGI_SURFACE_H
#define GPUGI_SURFACE_H
#include "device/ray.h"
#include "device/rng.h"
#include "shading/scene.h"
#include "shading/texture.h"
#include "shading/bsdf.h"

typedef struct {
    float3 p;      /* position */
    float3 ng;     /* geometric normal facing the incoming ray */
    float3 ns;     /* shading normal on the same side as ng */
    float3 smooth; /* the interpolated normal (ns before a normal map) */
    float3 ng_raw; /* geometric normal as wound */
    float2 uv;
    float2 bary;   /* barycentric weights of the hit's second and third corners */
    float3 tangent; /* an anisotropic material's tangent (world), zero otherwise */
    int tri;
    float eps;     /* offset for rays leaving this point */
} SurfacePoint;

/* At most this many rows in the chain of a mix of surfaces. */
#define SURFACE_MAX_MIX 16

/* The random number a shading event spends on picking one surface of a
 * mix; none without mixes, so other scenes keep their random streams. */
#ifdef SCENE_HAS_MIX
#define SURFACE_MIX_U(rng) Rng_next(rng)
#else
#define SURFACE_MIX_U(rng) 0.0f
#endif

/* The texture coordinates at a hit. */
inline float2 Surface_uv(const SceneView *sc, const Hit *hit) {
    int t = hit->tri;
    return (1.0f - hit->u - hit->v) * sc->uvs[3 * t] + hit->u * sc->uvs[3 * t + 1] + hit->v * sc->uvs[3 * t + 2];
}

/* The surface hit by a ray travelling along dir. */
inline SurfacePoint Surface_at(const SceneView *sc, float3 dir, const Hit *hit) {
    SurfacePoint s;
    int t = hit->tri;
    const __global float4 *verts = sc->tree.verts;
    float3 v0 = verts[3 * t].xyz, v1 = verts[3 * t + 1].xyz, v2 = verts[3 * t + 2].xyz;
    float w = 1.0f - hit->u - hit->v;
    s.p = w * v0 + hit->u * v1 + hit->v * v2;
    float3 cr = cross(v1 - v0, v2 - v0);
    float len = length(cr);
    s.ng_raw = len > 0.0f ? cr / len : (float3)(0.0f, 0.0f, 1.0f);
    s.ng = dot(s.ng_raw, dir) > 0.0f ? -s.ng_raw : s.ng_raw;
    const __global float4 *normals = sc->normals;
    float3 ns = w * normals[3 * t].xyz + hit->u * normals[3 * t + 1].xyz + hit->v * normals[3 * t + 2].xyz;
    float ls = length(ns);
    ns = ls > 1e-20f ? ns / ls : s.ng;
    s.ns = dot(ns, s.ng) < 0.0f ? -ns : ns;
    s.smooth = s.ns;
    s.uv = Surface_uv(sc, hit);
    s.bary = (float2)(hit->u, hit->v);
    s.tangent = (float3)(0.0f);
    s.tri = t;
    /* p is rounded like the largest vertex coordinate it was made from */
    s.eps = Ray_offset(fmax(fmax(Ray_magnitude(v0), Ray_magnitude(v1)), Ray_magnitude(v2)));
    return s;
}

/* The chance of stopping at row m of a mix's chain once the pick reached
 * it: its Fac texture's 1 - value where it has one, else mix_stop. */
inline float Surface_mix_stop(const SceneView *sc, const Material *m, float2 uv) {
#ifdef SCENE_HAS_TEXTURES
    if (m->mix_texture >= 0)
        return 1.0f - clamp(Texture_value(sc->atlas, sc->textures, m->mix_texture, m->mix_channel, uv), 0.0f, 1.0f);
#endif
    return m->mix_stop;
}

/* The material of one shading event at the triangle `tri`: its row, or
 * for a mix of surfaces one row of the chain, picked by u in [0, 1) with
 * each row's chance (its BSDF carries mix_scale, Bsdf_make). The emission
 * is the first row's, the mix's sum. */
inline Material Surface_material(const SceneView *sc, int tri, float2 uv, float u) {
    Material m = sc->materials[sc->material_of[tri]];
#ifdef SCENE_HAS_MIX
    float4 emission = m.emission;
    for (int i = 0; i < SURFACE_MAX_MIX && m.mix_next >= 0; ++i) {
        float stop = Surface_mix_stop(sc, &m, uv);
        if (u < stop) break;
        /* what is left of u picks among the rest */
        u = fmin((u - stop) / fmax(1.0f - stop, 1e-20f), 0.99999994f);
        m = sc->materials[m.mix_next];
    }
    m.emission = emission;
#endif
    return m;
}

/* The colour light keeps passing through a row's surface: a Transparent
 * shader's colour, white for any other (its alpha decides how often). */
inline float3 Surface_pass_tint(const Material *m) {
    return m->shader == MATERIAL_TRANSPARENT ? m->base_color.xyz : (float3)(1.0f);
}

/* The fraction of light a shadow ray passes through the triangle `tri` at
 * uv, per channel: 1 - alpha times the pass tint, over the rows of a mix
 * weighed by their chance and scale (a Transparent BSDF is a row of alpha 0). */
inline float3 Surface_transmittance(const SceneView *sc, int tri, float2 uv) {
    Material m = sc->materials[sc->material_of[tri]];
#ifdef SCENE_HAS_MIX
    float3 passed = (float3)(0.0f);
    float reach = 1.0f;
    for (int i = 0; i < SURFACE_MAX_MIX; ++i) {
        float stop = m.mix_next >= 0 ? Surface_mix_stop(sc, &m, uv) : 1.0f;
        passed += reach * stop * m.mix_scale * (1.0f - m.base_color.w) * Surface_pass_tint(&m);
        reach *= 1.0f - stop;
        if (m.mix_next < 0 || !(reach > 0.0f)) break;
        m = sc->materials[m.mix_next];
    }
    return clamp(passed, 0.0f, 1.0f);
#else
    return (1.0f - m.base_color.w) * Surface_pass_tint(&m);
#endif
}

/* 1 where the normal as wound faces the side the ray came from, else -1. */
inline float Surface_facing(const SurfacePoint *sp) { return dot(sp->ng_raw, sp->ng) > 0.0f ? 1.0f : -1.0f; }

/* The tangent at sp (in w its bitangent's sign) for the normal n as
 * wound, for a normal map or anisotropy: the corners' tangents interpolated
 * where the scene has them (the exporter's: MikkTSpace's, per vertex, as
 * Cycles uses them, or radial ones for Cycles' default anisotropic
 * tangent), else the triangle's UV direction made orthogonal to n with the
 * sign of the UV winding (the same as MikkTSpace's where UVs run along the
 * faces, as on a UV sphere). w = 0: no tangent (degenerate UVs). */
inline float4 Surface_tangent(const SceneView *sc, const SurfacePoint *sp, float3 n) {
    int t = sp->tri;
#ifdef SCENE_HAS_TANGENTS
    const __global float4 *corner = sc->tangents + 3 * t;
    float4 mikk = (1.0f - sp->bary.x - sp->bary.y) * corner[0] + sp->bary.x * corner[1] + sp->bary.y * corner[2];
    if (dot(mikk.xyz, mikk.xyz) > 1e-12f && mikk.w != 0.0f) return mikk;
#endif
    const __global float4 *verts = sc->tree.verts;
    float3 e1 = verts[3 * t + 1].xyz - verts[3 * t].xyz, e2 = verts[3 * t + 2].xyz - verts[3 * t].xyz;
    float2 d1 = sc->uvs[3 * t + 1] - sc->uvs[3 * t], d2 = sc->uvs[3 * t + 2] - sc->uvs[3 * t];
    float det = d1.x * d2.y - d2.x * d1.y;
    if (!(fabs(det) > 1e-20f)) return (float4)(0.0f);
    float3 tu = (e1 * d2.y - e2 * d1.y) / det, tv = (e2 * d1.x - e1 * d2.x) / det;
    float3 tangent = tu - n * dot(n, tu);
    float tl = length(tangent);
    if (!(tl > 0.0f) || !isfinite(tl)) return (float4)(0.0f);
    return (float4)(tangent / tl, dot(cross(sp->ng_raw, tu), tv) < 0.0f ? -1.0f : 1.0f);
}

/* The shading normal of a tangent-space normal map: texel c (0..1 per
 * channel, 0.5 flat) in the frame of the tangent (Surface_tangent) and its
 * bitangent, built from the normal as wound and turned back to face the
 * ray, as Cycles' Normal Map node; Strength blends it with the smooth
 * normal. Without a tangent the smooth normal is kept. */
inline void Surface_normal_map(const SceneView *sc, SurfacePoint *sp, float4 c, float strength) {
    /* the normal as wound (the side the ray came from flips it back below) */
    float facing = Surface_facing(sp);
    float3 n = facing * sp->ns;
    float4 t = Surface_tangent(sc, sp, n);
    if (t.w == 0.0f) return;
    float3 tangent = t.xyz;
    float3 b = t.w * cross(n, tangent);
    float3 m = 2.0f * c.xyz - 1.0f;
    float3 mapped = m.x * tangent + m.y * b + m.z * n;
    float ml = length(mapped);
    if (!(ml > 0.0f)) return;
    mapped = facing * mapped / ml;
    mapped = sp->ns + (mapped - sp->ns) * strength;
    /* kept on the side the ray came from, just above the surface at worst */
    float above = dot(mapped, sp->ng);
    if (above < 0.01f) mapped += (0.01f - above) * sp->ng;
    ml = length(mapped);
    if (ml > 0.0f && isfinite(ml)) sp->ns = mapped / ml;
}

/* The material at the point with its textures applied: Base Color times
 * its texture (the return value), Roughness and Metallic from theirs (in
 * m), the normal map's shading normal (in sp), and an anisotropic
 * material's tangent (in sp). Without textures in the scene, the
 * material's values. */
inline float3 Surface_textured(const SceneView *sc, Material *m, SurfacePoint *sp) {
    float3 base = m->base_color.xyz;
    if (m->aniso_x != m->aniso_y) {
        sp->tangent = Surface_tangent(sc, sp, Surface_facing(sp) * sp->ns).xyz;
    }
#ifdef SCENE_HAS_TEXTURES
    if (m->texture >= 0) base *= Texture_sample(sc->atlas, sc->textures, m->texture, sp->uv).xyz;
    if (m->roughness_texture >= 0)
        m->roughness = clamp(Texture_value(sc->atlas, sc->textures, m->roughness_texture, m->roughness_channel,
                                           sp->uv), 0.0f, 1.0f);
    if (m->metallic_texture >= 0)
        m->metallic = clamp(Texture_value(sc->atlas, sc->textures, m->metallic_texture, m->metallic_channel,
                                          sp->uv), 0.0f, 1.0f);
    if (m->normal_texture >= 0)
        Surface_normal_map(sc, sp, Texture_sample(sc->atlas, sc->textures, m->normal_texture, sp->uv),
                           m->normal_strength);
#endif
    return base;
}

/* The BSDF at sp for a ray that arrived along dir; `sample` as in
 * Bsdf_make. */
inline Bsdf Surface_bsdf(const SurfacePoint *sp, const Material *m, float3 base, float3 dir, int sample) {
    /* the wound normal facing the ray means entering the object */
    bool entering = dot(sp->ng_raw, sp->ng) > 0.0f;
    return Bsdf_make(m, base, -dir, sp->ns, sp->smooth, sp->ng, sp->tangent, entering, sample);
}

/* Where a ray leaving sp along the world direction dir starts: above the
 * surface, or below it for a transmitted one. */
inline float3 Surface_leave(const SurfacePoint *sp, float3 dir) {
    return sp->p + (dot(dir, sp->ng) < 0.0f ? -sp->eps : sp->eps) * sp->ng;
}

#endif
