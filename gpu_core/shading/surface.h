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

/* The BSDF at sp for a ray that arrived along dir; `sample` as in
 * Bsdf_make. */
inline Bsdf Surface_bsdf(const SurfacePoint *sp, const Material *m, float3 base, float3 dir, int sample) {
    /* the wound normal facing the ray means entering the object */
    bool entering = dot(sp->ng_raw, sp->ng) > 0.0f;
    return Bsdf_make(m, base, -dir, sp->ns, sp->ng, entering, sample);
}

/* Where a ray leaving sp along the world direction dir starts: above the
 * surface, or below it for a transmitted one. */
inline float3 Surface_leave(const SurfacePoint *sp, float3 dir) {
    return sp->p + (dot(dir, sp->ng) < 0.0f ? -sp->eps : sp->eps) * sp->ng;
}

#endif
