/* Lights in Cycles' units (Cycles 4.x/5.x, soft falloff on):
 *   point, power P:  radiant intensity P/(4 pi); with radius r, a disk of
 *                    radiance P/(4 pi^2 r^2) facing the receiver;
 *   spot:            the point light times smoothstep((cos - cos_half) *
 *                    spot_smooth) of the angle to its axis, no cosine term;
 *   sun, strength S: irradiance S at normal incidence, spread over a disk of
 *                    directions of the given angular diameter;
 *   area, power P:   one-sided (along its -Z) radiance P/(pi A);
 *   emissive meshes: radiance = emission colour x strength, both faces;
 *   world:           radiance = colour x strength.
 * Samplers give, for a point x, the direction towards a sampled light
 * point, the shadow-ray length, the radiance arriving over the sample's
 * solid-angle pdf (no receiver cosine) and that pdf (0 for a point light
 * of radius 0 or a sun of angle 0: a direction no other sampling can
 * find). Light_seen gives what a ray sees on a light, and the pdf with
 * which the sampler would have chosen that direction (for multiple
 * importance sampling): lights are see-through emitters, as in Cycles, and
 * never cast shadows themselves. */
#ifndef GPUGI_LIGHTS_H
#define GPUGI_LIGHTS_H
#include "device/structs.h"
#include "device/sampling.h"
#include "device/ray.h"

#define LIGHT_FAR RAY_FAR

typedef struct {
    float3 dir;   /* unit, from x towards the light */
    float dist;   /* shadow ray length; LIGHT_FAR for sun and world */
    float3 value; /* radiance arriving / pdf */
    float pdf;    /* solid-angle pdf of dir; 0 for a singular light */
} LightSample;

/* Emissive triangles chosen by a power CDF (one light of kind LIGHT_MESH). */
typedef struct {
    const __global int *tris;   /* emissive triangle ids */
    const __global float *cdf;  /* inclusive CDF over tris, last = 1 */
    int count;
    const __global float4 *verts;
    const __global int *tri_material;
    const __global Material *materials;
} Emitters;

inline LightSample Light_none(void) {
    LightSample s;
    s.dir = (float3)(0.0f, 0.0f, 1.0f);
    s.dist = 0.0f;
    s.value = (float3)(0.0f);
    s.pdf = 0.0f;
    return s;
}

/* Spot cone falloff for a direction leaving the light. */
inline float Light_spot_attenuation(const Light *l, float3 from_light) {
    float x = clamp((dot(from_light, l->direction.xyz) - l->cos_half) * l->spot_smooth, 0.0f, 1.0f);
    return x * x * (3.0f - 2.0f * x);
}

/* Point and spot lights: a uniform point on the disk of radius r centred on
 * the light and facing x. Per sample P cos_disk / (4 pi t^2), which
 * integrates to P / (4 pi d^2) for a small disk and stays finite when x
 * comes closer than r. */
inline LightSample Light_sample_point(const Light *l, float3 x, float u1, float u2) {
    float3 c = l->position.xyz;
    float3 to_x = x - c;
    float d = length(to_x);
    if (!(d > 0.0f)) return Light_none();
    float3 axis = to_x / d;
    float3 y = c;
    if (l->radius > 0.0f) {
        float3 t, b;
        Sampling_frame(axis, &t, &b);
        float2 dk = Sampling_disk(u1, u2) * l->radius;
        y = c + dk.x * t + dk.y * b;
    }
    float3 to_y = y - x;
    float dist = length(to_y);
    if (!(dist > 0.0f)) return Light_none();
    LightSample s;
    s.dir = to_y / dist;
    s.dist = Ray_shadow_length(dist, y);
    float cos_disk = l->radius > 0.0f ? fmax(0.0f, -dot(axis, s.dir)) : 1.0f;
    float atten = l->kind == LIGHT_SPOT ? Light_spot_attenuation(l, -s.dir) : 1.0f;
    s.value = l->power.xyz * (atten * cos_disk / (4.0f * PI_F * fmax(dist * dist, 1e-30f)));
    float area = PI_F * l->radius * l->radius;
    s.pdf = l->radius > 0.0f && cos_disk > 0.0f ? dist * dist / (area * cos_disk) : 0.0f;
    return s;
}

/* Solid-angle pdf of a direction in the sun's disk (0: a singular sun). */
inline float Light_sun_pdf(const Light *l) {
    return l->cos_half < 1.0f ? 1.0f / (2.0f * PI_F * (1.0f - l->cos_half)) : 0.0f;
}

/* Sun: a uniform direction in its cone; S sun_norm per sample. */
inline LightSample Light_sample_sun(const Light *l, float u1, float u2) {
    LightSample s;
    float3 toward = -l->direction.xyz;
    s.dir = l->cos_half < 1.0f ? Sampling_cone(toward, l->cos_half, u1, u2) : toward;
    s.dist = LIGHT_FAR;
    s.value = l->power.xyz * l->sun_norm;
    s.pdf = Light_sun_pdf(l);
    return s;
}

/* A rectangle light seen from x, in a frame at x: its unit axes (ez away
 * from x's side), the corner (x0, y0, z0 < 0), the far corner (x1, y1),
 * the z components of the normals of the four planes through x and an
 * edge, the partial angles a[i] and the solid angle (their sum). */
typedef struct {
    float3 ex, ey, ez;
    float x0, y0, z0, x1, y1;
    float nz[4], a[4];
    float solid;
} LightRect;

/* Interior angles are pi/2 + asin(n_i . n_i+1), and n_i . n_i+1 equals the
 * product of their z components; summing the asin terms avoids the
 * cancellation of "angles - 2 pi" for small solid angles (Urena et al.
 * 2013). Returns false when the solid angle is too small for float32,
 * where area sampling is as good. */
inline bool Light_rect_from(const Light *l, float3 x, LightRect *r) {
    float len_u = length(l->axis_u.xyz), len_v = length(l->axis_v.xyz);
    r->ex = l->axis_u.xyz / len_u;
    r->ey = l->axis_v.xyz / len_v;
    r->ez = cross(r->ex, r->ey);
    float3 d = l->position.xyz - 0.5f * (l->axis_u.xyz + l->axis_v.xyz) - x;
    r->z0 = dot(d, r->ez);
    if (r->z0 > 0.0f) {
        r->ez = -r->ez;
        r->z0 = -r->z0;
    }
    r->x0 = dot(d, r->ex);
    r->y0 = dot(d, r->ey);
    r->x1 = r->x0 + len_u;
    r->y1 = r->y0 + len_v;
    float z0 = r->z0;
    r->nz[0] = -r->y0 / sqrt(z0 * z0 + r->y0 * r->y0);
    r->nz[1] = r->x1 / sqrt(z0 * z0 + r->x1 * r->x1);
    r->nz[2] = r->y1 / sqrt(z0 * z0 + r->y1 * r->y1);
    r->nz[3] = -r->x0 / sqrt(z0 * z0 + r->x0 * r->x0);
    r->solid = 0.0f;
    for (int i = 0; i < 4; ++i) {
        r->a[i] = asin(clamp(r->nz[i] * r->nz[(i + 1) % 4], -1.0f, 1.0f));
        r->solid += r->a[i];
    }
    return r->solid > 1e-4f && z0 < 0.0f;
}

/* Rectangle light: a direction uniform in its solid angle, by inverting
 * the solid angle cumulative along x, then along y. The angle's cosine and
 * sine are Sampling_cos_sin's (the native pair on PoCL, where the accurate one
 * with its argument reduction took 6% of a Cornell-box image). With
 * g = 1 / cos^2 of the sampled edge angle, the x of the sampled line is
 * |z0| / sqrt(g - 1) with the sign of fu, and distances stay squared until
 * a root is needed: five roots and six divisions where the textbook form
 * takes seven and eight, most of them one after another. */
inline void Light_sample_rect_solid_angle(const Light *l, const LightRect *r, float3 x, float u1, float u2,
                                          LightSample *s) {
    float au = u1 * r->solid + PI_F - r->a[2] - r->a[3];
    float2 cs = Sampling_cos_sin(au);
    float fu = (cs.x * r->nz[0] - r->nz[2]) / cs.y;
    float g = fu * fu + r->nz[0] * r->nz[0];
    float z0 = r->z0;
    float xu = clamp(copysign(z0, fu) / sqrt(fmax(g - 1.0f, 1e-14f)), r->x0, r->x1); /* z0 < 0 */
    float dd2 = xu * xu + z0 * z0;
    float h0 = r->y0 / sqrt(dd2 + r->y0 * r->y0), h1 = r->y1 / sqrt(dd2 + r->y1 * r->y1);
    float hv = h0 + u2 * (h1 - h0);
    float yv = hv * hv < 1.0f - 1e-6f ? hv * sqrt(dd2 / (1.0f - hv * hv)) : r->y1;
    float3 to_y = xu * r->ex + yv * r->ey + z0 * r->ez;
    float dist = sqrt(dd2 + yv * yv);
    s->dir = to_y * (1.0f / dist);
    s->dist = Ray_shadow_length(dist, x + to_y);
    s->value = l->radiance.xyz * r->solid; /* x on the emitting side: Light_sample_area */
    s->pdf = 1.0f / r->solid;
}

/* Area of an area light. */
inline float Light_area(const Light *l) {
    float a = length(cross(l->axis_u.xyz, l->axis_v.xyz));
    return l->shape == AREA_ELLIPSE ? 0.25f * PI_F * a : a;
}

/* Area light: rectangles by solid angle where it is large enough; else a
 * uniform point on the rectangle or ellipse, where radiance P/(pi A) over
 * the pdf t^2 / (A cos_y) gives P cos_y / (pi t^2). */
inline LightSample Light_sample_area(const Light *l, float3 x, float u1, float u2) {
    /* one-sided: nothing reaches x behind (or in) the light's plane, so no
     * sample is drawn there (the ceiling above a Cornell box's light) */
    if (!(dot(x - l->position.xyz, l->direction.xyz) > 0.0f)) return Light_none();
    LightSample s;
    LightRect r;
    if (l->shape == AREA_RECTANGLE && Light_rect_from(l, x, &r)) {
        Light_sample_rect_solid_angle(l, &r, x, u1, u2, &s);
        return s;
    }
    float2 q = l->shape == AREA_ELLIPSE ? 0.5f * Sampling_disk(u1, u2) : (float2)(u1 - 0.5f, u2 - 0.5f);
    float3 y = l->position.xyz + q.x * l->axis_u.xyz + q.y * l->axis_v.xyz;
    float3 to_y = y - x;
    float dist = length(to_y);
    if (!(dist > 0.0f)) return Light_none();
    s.dir = to_y / dist;
    s.dist = Ray_shadow_length(dist, y);
    float cos_y = fmax(0.0f, -dot(l->direction.xyz, s.dir));
    s.value = l->power.xyz * (cos_y / (PI_F * fmax(dist * dist, 1e-30f)));
    float area = Light_area(l);
    s.pdf = cos_y > 0.0f && area > 0.0f ? dist * dist / (area * cos_y) : 0.0f;
    return s;
}

/* Emissive triangles: index of triangle tri among em->tris (sorted), or -1. */
inline int Light_mesh_index(const Emitters *em, int tri) {
    int lo = 0, hi = em->count - 1;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (em->tris[mid] < tri) lo = mid + 1; else hi = mid;
    }
    return em->count > 0 && em->tris[lo] == tri ? lo : -1;
}

/* Probability of picking emissive triangle k. */
inline float Light_mesh_pick(const Emitters *em, int k) {
    return em->cdf[k] - (k > 0 ? em->cdf[k - 1] : 0.0f);
}

/* Solid-angle pdf of reaching emissive triangle tri at distance t along
 * dir from the mesh light's sampler (the mesh row picked). */
inline float Light_mesh_pdf(const Emitters *em, int tri, float3 dir, float t) {
    int k = Light_mesh_index(em, tri);
    if (k < 0) return 0.0f;
    float3 v0 = em->verts[3 * tri].xyz, v1 = em->verts[3 * tri + 1].xyz, v2 = em->verts[3 * tri + 2].xyz;
    float3 cr = cross(v1 - v0, v2 - v0);
    float len_cr = length(cr);
    float cos_y = len_cr > 0.0f ? fabs(dot(cr, dir)) / len_cr : 0.0f;
    if (!(cos_y > 0.0f)) return 0.0f;
    return Light_mesh_pick(em, k) * t * t / (0.5f * len_cr * cos_y);
}

/* Emissive triangles: pick one by power, then a uniform point on it. */
inline LightSample Light_sample_mesh(const Emitters *em, float3 x, float u0, float u1, float u2) {
    if (em->count <= 0) return Light_none();
    int lo = 0, hi = em->count - 1;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (em->cdf[mid] <= u0) lo = mid + 1; else hi = mid;
    }
    float pick = Light_mesh_pick(em, lo);
    if (!(pick > 0.0f)) return Light_none();
    int tri = em->tris[lo];
    float3 v0 = em->verts[3 * tri].xyz, v1 = em->verts[3 * tri + 1].xyz, v2 = em->verts[3 * tri + 2].xyz;
    float2 bc = Sampling_triangle(u1, u2);
    float3 y = v0 + bc.x * (v1 - v0) + bc.y * (v2 - v0);
    float3 cr = cross(v1 - v0, v2 - v0);
    float len_cr = length(cr);
    float3 to_y = y - x;
    float dist = length(to_y);
    if (!(dist > 0.0f && len_cr > 0.0f)) return Light_none();
    LightSample s;
    s.dir = to_y / dist;
    s.dist = Ray_shadow_length(dist, y);
    float cos_y = fabs(dot(cr / len_cr, s.dir));
    float3 le = em->materials[em->tri_material[tri]].emission.xyz;
    s.value = le * (cos_y * (0.5f * len_cr) / (fmax(dist * dist, 1e-30f) * pick));
    s.pdf = cos_y > 0.0f ? pick * dist * dist / (0.5f * len_cr * cos_y) : 0.0f;
    return s;
}

/* Uniform world of radiance L, by cosine sampling around n. */
inline LightSample Light_sample_world(float3 world, float3 n, float u1, float u2) {
    LightSample s;
    s.dir = Sampling_cosine(n, u1, u2);
    s.dist = LIGHT_FAR;
    s.pdf = fmax(dot(n, s.dir), 0.0f) / PI_F;
    s.value = s.pdf > 0.0f ? world / s.pdf : (float3)(0.0f);
    return s;
}

/* One sample of light l (sun, point, spot, area, mesh). */
inline LightSample Light_sample(const Light *l, const Emitters *em, float3 x, float u0, float u1, float u2) {
    if (l->kind == LIGHT_SUN) return Light_sample_sun(l, u1, u2);
    if (l->kind == LIGHT_AREA) return Light_sample_area(l, x, u1, u2);
    if (l->kind == LIGHT_MESH) return Light_sample_mesh(em, x, u0, u1, u2);
    return Light_sample_point(l, x, u1, u2);
}

/* Radiance a ray (org, dir) sees on a point, spot or area light between
 * tmin and tmax, zero when it misses, and in *pdf the solid-angle pdf with which
 * Light_sample picks that direction from org. Area lights show only their
 * emitting side; point and spot lights show their disk facing the ray
 * origin. */
inline float3 Light_seen(const Light *l, float3 org, float3 dir, float tmin, float tmax, float *pdf) {
    float3 none = (float3)(0.0f);
    *pdf = 0.0f;
    if (!(l->radiance.x > 0.0f || l->radiance.y > 0.0f || l->radiance.z > 0.0f)) return none;
    float3 c = l->position.xyz;
    float3 nrm;
    if (l->kind == LIGHT_AREA) {
        nrm = l->direction.xyz;
    } else if (l->kind == LIGHT_POINT || l->kind == LIGHT_SPOT) {
        float3 from_c = org - c;
        float dc = length(from_c);
        if (!(dc > 0.0f)) return none;
        nrm = from_c / dc;
    } else {
        return none;
    }
    float dn = dot(dir, nrm);
    if (!(dn < 0.0f)) return none; /* one-sided: only rays travelling against the normal */
    float t = dot(c - org, nrm) / dn;
    if (!(t > fmax(tmin, 0.0f) && t < tmax)) return none;
    float3 q = org + t * dir - c;
    if (l->kind == LIGHT_AREA) {
        float a = dot(q, l->axis_u.xyz) / dot(l->axis_u.xyz, l->axis_u.xyz);
        float b = dot(q, l->axis_v.xyz) / dot(l->axis_v.xyz, l->axis_v.xyz);
        bool inside = l->shape == AREA_ELLIPSE ? (a * a + b * b <= 0.25f) : (fabs(a) <= 0.5f && fabs(b) <= 0.5f);
        if (!inside) return none;
        LightRect r;
        if (l->shape == AREA_RECTANGLE && Light_rect_from(l, org, &r)) *pdf = 1.0f / r.solid;
        else *pdf = t * t / fmax(Light_area(l) * -dn, 1e-30f);
        return l->radiance.xyz;
    }
    if (dot(q, q) > l->radius * l->radius) return none;
    *pdf = t * t / fmax(PI_F * l->radius * l->radius * -dn, 1e-30f);
    float atten = l->kind == LIGHT_SPOT ? Light_spot_attenuation(l, -dir) : 1.0f;
    return l->radiance.xyz * atten;
}

/* Radiance an escaping ray sees on a sun's disk (pdf as Light_seen). */
inline float3 Light_sun_seen(const Light *l, float3 dir, float *pdf) {
    *pdf = 0.0f;
    if (l->kind != LIGHT_SUN || !(l->cos_half < 1.0f)) return (float3)(0.0f);
    if (dot(dir, -l->direction.xyz) < l->cos_half) return (float3)(0.0f);
    *pdf = Light_sun_pdf(l);
    return l->radiance.xyz;
}

#endif
