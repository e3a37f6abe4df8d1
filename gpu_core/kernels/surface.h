/* The surface at a ray hit: position, normals facing the ray, UV, material,
 * and the offset for rays leaving it. Shared by every kernel that shades. */
#ifndef GPUGI_SURFACE_H
#define GPUGI_SURFACE_H
#include "types.h"
#include "ray.h"
#include "texture.h"
#include "kdtree_traverse.h"
#include "bsdf.h"

typedef struct {
    float3 p;      /* position */
    float3 ng;     /* geometric normal facing the incoming ray */
    float3 ns;     /* shading normal on the same side as ng */
    float3 ng_raw; /* geometric normal as wound */
    float2 uv;
    int material;
    float eps;     /* offset for rays leaving this point */
} SurfacePoint;

/* Triangle attributes every shading kernel takes, in this order (host:
 * the renderer's uploaded scene). */
#define SURFACE_PARAMS                                                       \
    const __global float4 *tri_normals, const __global float2 *tri_uvs,     \
        const __global int *tri_material, const __global Material *materials, \
        const __global float4 *tex_atlas, const __global TextureInfo *tex_infos

inline SurfacePoint Surface_at(const KdTree *tree, const __global float4 *tri_normals,
                               const __global float2 *tri_uvs, const __global int *tri_material,
                               float3 dir, const Hit *hit) {
    SurfacePoint s;
    int t = hit->tri;
    float3 v0 = tree->verts[3 * t].xyz, v1 = tree->verts[3 * t + 1].xyz, v2 = tree->verts[3 * t + 2].xyz;
    float w = 1.0f - hit->u - hit->v;
    s.p = w * v0 + hit->u * v1 + hit->v * v2;
    float3 cr = cross(v1 - v0, v2 - v0);
    float len = length(cr);
    s.ng_raw = len > 0.0f ? cr / len : (float3)(0.0f, 0.0f, 1.0f);
    s.ng = dot(s.ng_raw, dir) > 0.0f ? -s.ng_raw : s.ng_raw;
    float3 ns = w * tri_normals[3 * t].xyz + hit->u * tri_normals[3 * t + 1].xyz + hit->v * tri_normals[3 * t + 2].xyz;
    float ls = length(ns);
    ns = ls > 1e-20f ? ns / ls : s.ng;
    s.ns = dot(ns, s.ng) < 0.0f ? -ns : ns;
    s.uv = w * tri_uvs[3 * t] + hit->u * tri_uvs[3 * t + 1] + hit->v * tri_uvs[3 * t + 2];
    s.material = tri_material[t];
    /* p is rounded like the largest vertex coordinate it was made from */
    s.eps = Ray_offset(fmax(fmax(Ray_magnitude(v0), Ray_magnitude(v1)), Ray_magnitude(v2)));
    return s;
}

/* Base colour at the point, texture included. */
inline float3 Surface_base(const Material *m, const __global float4 *tex_atlas,
                           const __global TextureInfo *tex_infos, float2 uv) {
    float3 base = m->base_color.xyz;
    if (m->texture >= 0) base *= Texture_sample(tex_atlas, tex_infos, m->texture, uv).xyz;
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
