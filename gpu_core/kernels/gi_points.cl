/* Shading points for the irradiance cache [WZPB09]: camera rays through a
 * grid of sub-pixel positions (so pixels on an edge see both surfaces),
 * followed through mirrors and glass (the likelier of reflection and
 * refraction) to the first surface with a diffuse lobe. */
#include "types.h"
#include "sampling.h"
#include "camera.h"
#include "bsdf.h"
#include "surface.h"

#define GI_POINTS_MAX_PASSTHROUGH 64
/* Points step back along the ray by this fraction of the scene's size: a
 * point on the edge where two walls meet then lies off both, and its gather
 * rays hit the other wall instead of slipping out past it. */
#define GI_POINTS_PULL_BACK 1e-5f

/* Per point (sub-pixel s of pixel p is point p * sub^2 + s, sub positions
 * row by row): position (w = 1 where a diffuse surface was found, else 0)
 * and shading normal facing the camera path. */
__kernel void GiPoints_trace(KDTREE_PARAMS, SURFACE_PARAMS, const __global Camera *camera,
                             const int4 window, const int sub, const int max_bounces,
                             __global float4 *out_pos, __global float4 *out_nrm) {
    int g = get_global_id(0);
    int w = window.z - window.x, h = window.w - window.y;
    if (g >= w * h * sub * sub) return;
    int pixel = g / (sub * sub), s = g % (sub * sub);
    KdTree tree = KDTREE_MAKE();
    Camera cam = camera[0];
    float3 org, dir;
    float tmin, tmax;
    Camera_ray(&cam, window.x + pixel % w + (s % sub + 0.5f) / sub, window.y + pixel / w + (s / sub + 0.5f) / sub,
               &org, &dir, &tmin, &tmax);
    float pull_back = GI_POINTS_PULL_BACK * length(tree.bmax - tree.bmin);
    out_pos[g] = (float4)(0.0f);
    out_nrm[g] = (float4)(0.0f);
    int bounces = 0, passes = 0;
    while (true) {
        Hit hit;
        if (!KdTree_intersect(&tree, org, dir, tmin, tmax, &hit)) return;
        SurfacePoint sp = Surface_at(&tree, tri_normals, tri_uvs, tri_material, dir, &hit);
        Material m = materials[sp.material];
        /* mostly see-through surfaces are passed, as most camera samples do */
        if (m.base_color.w < 0.5f && passes < GI_POINTS_MAX_PASSTHROUGH) {
            passes++;
            org = sp.p - sp.eps * sp.ng;
            tmin = 0.0f;
            tmax = RAY_FAR;
            continue;
        }
        float diffuse = Surface_diffuse_weight(&m);
        if (diffuse > 0.0f || bounces >= max_bounces) {
            out_pos[g] = (float4)(sp.p - pull_back * dir, diffuse > 0.0f ? 1.0f : 0.0f);
            out_nrm[g] = (float4)(sp.ns, 0.0f);
            return;
        }
        /* a purely specular surface: follow its likelier direction */
        bool refracted = false;
        if (m.metallic >= 0.5f || m.transmission <= 0.0f) {
            dir = Bsdf_mirror(dir, sp.ns, sp.ng);
        } else {
            bool entering = dot(sp.ng_raw, sp.ng) > 0.0f;
            float cos_t;
            float eta = entering ? 1.0f / m.ior : m.ior;
            float f = Bsdf_fresnel(fabs(dot(dir, sp.ns)), eta, &cos_t);
            dir = Bsdf_glass(dir, sp.ns, sp.ng, entering, m.ior, f < 0.5f ? 1.0f : 0.0f, &refracted);
        }
        org = sp.p + (refracted ? -sp.eps : sp.eps) * sp.ng;
        tmin = 0.0f;
        tmax = RAY_FAR;
        bounces++;
    }
}
