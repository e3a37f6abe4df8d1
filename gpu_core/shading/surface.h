/* The surface at a ray hit: position, normals facing the ray, UV, material,
 * and the offset for rays leaving it. Shared by every kernel that shades. */
#ifndef GPUGI_SURFACE_H
#define GPUGI_SURFACE_H
#include "device/ray.h"
#include "shading/scene.h"
#include "shading/texture.h"
#include "shading/bsdf.h"

typedef struct {
    float3 p;      /* position */
    float3 ng;     /* geometric normal facing the incoming ray */
    float3 ns;     /* shading normal on the same side as ng */
    float3 ng_raw; /* geometric normal as wound */
    float2 uv;
    int material;
    float eps;     /* offset for rays leaving this point */
} SurfacePoint;

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
    s.uv = w * sc->uvs[3 * t] + hit->u * sc->uvs[3 * t + 1] + hit->v * sc->uvs[3 * t + 2];
    s.material = sc->material_of[t];
    /* p is rounded like the largest vertex coordinate it was made from */
    s.eps = Ray_offset(fmax(fmax(Ray_magnitude(v0), Ray_magnitude(v1)), Ray_magnitude(v2)));
    return s;
}

/* Base colour at the point, texture included (with textures in the scene). */
inline float3 Surface_base(const SceneView *sc, const Material *m, float2 uv) {
    float3 base = m->base_color.xyz;
#ifdef SCENE_HAS_TEXTURES
    if (m->texture >= 0) base *= Texture_sample(sc->atlas, sc->textures, m->texture, uv).xyz;
#endif
    return base;
}

/* Weight of the diffuse lobe among the Principled lobes (see Bsdf_pick). */
inline float Surface_diffuse_weight(const Material *m) {
    float w_mirror = clamp(m->metallic, 0.0f, 1.0f);
    float w_glass = (1.0f - w_mirror) * clamp(m->transmission, 0.0f, 1.0f);
    return fmax(0.0f, 1.0f - w_mirror - w_glass);
}

/* Scatter off a specular lobe at sp (BSDF_MIRROR, or BSDF_GLASS with u
 * choosing Fresnel reflection or refraction): writes the new direction, the
 * next ray's origin and whether it refracted, and returns the colour the ray
 * is tinted by (the base colour; white for a reflection off glass). */
inline float3 Surface_specular(const SurfacePoint *sp, const Material *m, int lobe, float3 base, float u,
                               float3 *dir, float3 *org, bool *refracted) {
    *refracted = false;
    float3 tint = base;
    if (lobe == BSDF_MIRROR) {
        *dir = Bsdf_mirror(*dir, sp->ns, sp->ng);
    } else {
        /* the wound normal facing the ray means entering the object */
        bool entering = dot(sp->ng_raw, sp->ng) > 0.0f;
        *dir = Bsdf_glass(*dir, sp->ns, sp->ng, entering, m->ior, u, refracted);
        if (!*refracted) tint = (float3)(1.0f);
    }
    *org = sp->p + (*refracted ? -sp->eps : sp->eps) * sp->ng;
    return tint;
}

#endif
