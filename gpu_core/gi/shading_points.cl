/* Shading points for the irradiance cache [WZPB09]: camera rays through a
 * grid of sub-pixel positions (so pixels on an edge see both surfaces),
 * followed through singular surfaces (mirrors and smooth glass: the
 * likelier of their directions) to the first surface with a smooth lobe;
 * it holds a point where it has a diffuse lobe (a glossy-only surface has
 * none: camera paths go on from it and read the cut, image.cl). */
#include "device/launch.h"
#include "device/sampling.h"
#include "shading/camera.h"
#include "shading/surface.h"

#define SHADING_POINTS_MAX_PASSTHROUGH 64
/* Points step back along the ray by this fraction of the scene's size: a
 * point on the edge where two walls meet then lies off both, and its gather
 * rays hit the other wall instead of slipping out past it. */
#define SHADING_POINTS_PULL_BACK 1e-5f

/* Per grid slot (sub-pixel s of pixel p of the window is slot p * sub^2 +
 * s, sub positions row by row): position (w = 1 where a diffuse surface was
 * found, else 0) and shading normal facing the camera path. window = (x0,
 * y0, x1, y1) of the full image. */
__kernel void ShadingPoints_trace(SCENE_PARAMS, const int4 window, const int sub, const int max_bounces,
                                  __global float4 *out_pos, __global float4 *out_nrm) {
    int g = Launch_global_id();
    int w = window.z - window.x, h = window.w - window.y;
    if (g >= w * h * sub * sub) return;
    int pixel = g / (sub * sub), s = g % (sub * sub);
    SceneView sc = SCENE_MAKE();
    Camera cam = *sc.camera;
    float3 org, dir;
    float tmin, tmax;
    Camera_ray(&cam, window.x + pixel % w + (s % sub + 0.5f) / sub, window.y + pixel / w + (s / sub + 0.5f) / sub,
               &org, &dir, &tmin, &tmax);
    float pull_back = SHADING_POINTS_PULL_BACK * length(sc.tree.bmax - sc.tree.bmin);
    out_pos[g] = (float4)(0.0f);
    out_nrm[g] = (float4)(0.0f);
    int bounces = 0, passes = 0;
    while (true) {
        Hit hit;
        if (!KdTree_intersect(&sc.tree, org, dir, tmin, tmax, &hit)) return;
        SurfacePoint sp = Surface_at(&sc, dir, &hit);
        Rng pick = Rng_make((uint)g, (uint)(bounces + passes), 0x6d697821U);
        Material m = Surface_material(&sc, sp.tri, sp.uv, SURFACE_MIX_U(&pick));
        /* mostly see-through surfaces are passed, as most camera samples do */
        if (m.base_color.w < 0.5f && passes < SHADING_POINTS_MAX_PASSTHROUGH) {
            passes++;
            org = sp.p - sp.eps * sp.ng;
            tmin = 0.0f;
            tmax = RAY_FAR;
            continue;
        }
        float3 base = Surface_textured(&sc, &m, &sp);
        Bsdf f = Surface_bsdf(&sp, &m, base, dir, BSDF_SAMPLE_ALL);
        bool diffuse = f.diffuse.x > 0.0f || f.diffuse.y > 0.0f || f.diffuse.z > 0.0f;
        float3 wi;
        if (Bsdf_has_smooth(&f) || bounces >= max_bounces || !Bsdf_likeliest(&f, &wi)) {
            out_pos[g] = (float4)(sp.p - pull_back * dir, diffuse ? 1.0f : 0.0f);
            out_nrm[g] = (float4)(sp.ns, 0.0f);
            return;
        }
        /* a singular surface: follow its likelier direction */
        dir = Bsdf_to_world(&f, wi);
        org = Surface_leave(&sp, dir);
        tmin = 0.0f;
        tmax = RAY_FAR;
        bounces++;
    }
}

/* The value of each compacted point into its grid slot, non-finite parts
 * as 0 (the other slots stay as they were: zero). */
__kernel void ShadingPoints_scatter(const __global float4 *values, const __global int *slots, const int n,
                                    __global float4 *grid) {
    int i = Launch_global_id();
    if (i >= n) return;
    float4 v = values[i];
    grid[slots[i]] = (float4)(isfinite(v.x) ? v.x : 0.0f, isfinite(v.y) ? v.y : 0.0f, isfinite(v.z) ? v.z : 0.0f,
                              isfinite(v.w) ? v.w : 0.0f);
}

/* 1 where a grid slot holds a point. */
__kernel void ShadingPoints_found(const __global float4 *grid_pos, const int n, __global int *flags) {
    int i = Launch_global_id();
    if (i < n) flags[i] = grid_pos[i].w > 0.0f;
}

/* The pixel (x, y) in the window of each point, from its slot. */
__kernel void ShadingPoints_pixels(const __global int *slots, const int n, const int width, const int sub2,
                                   __global int2 *pixels) {
    int i = Launch_global_id();
    if (i >= n) return;
    int p = slots[i] / sub2;
    pixels[i] = (int2)(p % width, p / width);
}
