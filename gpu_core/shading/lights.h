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
 * Samplers give an estimate of the irradiance a light gives the point x
 * with normal n (receiver cosine included), the direction towards the
 * sampled light point and the shadow-ray length. Light_seen gives what a
 * ray sees on a light: lights are see-through emitters, as in Cycles, and
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
    float3 value; /* irradiance estimate (W/m^2), receiver cosine included */
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
    return s;
}

/* Spot cone falloff for a direction leaving the light. */
inline float Light_spot_attenuation(const Light *l, float3 from_light) {
    float x = clamp((dot(from_light, l->direction.xyz) - l->cos_half) * l->spot_smooth, 0.0f, 1.0f);
    return x * x * (3.0f - 2.0f * x);
}

/* Point and spot lights: a uniform point on the disk of radius r centred on
 * the light and facing x. Per sample P cos_disk cos_x / (4 pi t^2), which
 * integrates to P cos_x / (4 pi d^2) for a small disk and stays finite when
 * x comes closer than r. */
inline LightSample Light_sample_point(const Light *l, float3 x, float3 n, float u1, float u2) {
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
    float cos_x = fmax(0.0f, dot(n, s.dir));
    float atten = l->kind == LIGHT_SPOT ? Light_spot_attenuation(l, -s.dir) : 1.0f;
    s.value = l->power.xyz * (atten * cos_disk * cos_x / (4.0f * PI_F * fmax(dist * dist, 1e-30f)));
    return s;
}

/* Sun: a uniform direction in its cone; S sun_norm cos_x per sample. */
inline LightSample Light_sample_sun(const Light *l, float3 n, float u1, float u2) {
    LightSample s;
    float3 toward = -l->direction.xyz;
    s.dir = l->cos_half < 1.0f ? Sampling_cone(toward, l->cos_half, u1, u2) : toward;
    s.dist = LIGHT_FAR;
    s.value = l->power.xyz * (l->sun_norm * fmax(0.0f, dot(n, s.dir)));
    return s;
}

/* Rectangle light seen from x: a direction uniform in its solid angle
 * (spherical rectangle sampling after Urena et al. 2013). Each sample
 * estimates radiance x cos_x x solid angle. Returns false when the solid
 * angle is too small for float32, where area sampling is as good. */
inline bool Light_sample_rect_solid_angle(const Light *l, float3 x, float3 n, float u1, float u2,
                                          LightSample *s) {
    float len_u = length(l->axis_u.xyz), len_v = length(l->axis_v.xyz);
    float3 ex = l->axis_u.xyz / len_u, ey = l->axis_v.xyz / len_v;
    float3 ez = cross(ex, ey);
    /* the rectangle in a frame at x: corner (x0, y0, z0), z0 < 0 */
    float3 d = l->position.xyz - 0.5f * (l->axis_u.xyz + l->axis_v.xyz) - x;
    float z0 = dot(d, ez);
    if (z0 > 0.0f) {
        ez = -ez;
        z0 = -z0;
    }
    float x0 = dot(d, ex), y0 = dot(d, ey);
    float x1 = x0 + len_u, y1 = y0 + len_v;
    /* normals of the four planes through x and an edge, z components */
    float n0z = -y0 / sqrt(z0 * z0 + y0 * y0);
    float n1z = x1 / sqrt(z0 * z0 + x1 * x1);
    float n2z = y1 / sqrt(z0 * z0 + y1 * y1);
    float n3z = -x0 / sqrt(z0 * z0 + x0 * x0);
    /* interior angles are pi/2 + asin(n_i . n_i+1), and n_i . n_i+1 equals
     * the product of their z components; summing the asin terms avoids the
     * cancellation of "angles - 2 pi" for small solid angles */
    float a0 = asin(clamp(n0z * n1z, -1.0f, 1.0f)), a1 = asin(clamp(n1z * n2z, -1.0f, 1.0f));
    float a2 = asin(clamp(n2z * n3z, -1.0f, 1.0f)), a3 = asin(clamp(n3z * n0z, -1.0f, 1.0f));
    float solid = a0 + a1 + a2 + a3;
    if (!(solid > 1e-4f) || !(z0 < 0.0f)) return false;
    /* invert the solid angle cumulative along x, then along y */
    float au = u1 * solid + PI_F - a2 - a3;
    float fu = (cos(au) * n0z - n2z) / sin(au);
    float cu = clamp(copysign(1.0f, fu) / sqrt(fu * fu + n0z * n0z), -1.0f, 1.0f);
    float xu = clamp(-(cu * z0) / fmax(sqrt(1.0f - cu * cu), 1e-7f), x0, x1);
    float dd = sqrt(xu * xu + z0 * z0);
    float h0 = y0 / sqrt(dd * dd + y0 * y0), h1 = y1 / sqrt(dd * dd + y1 * y1);
    float hv = h0 + u2 * (h1 - h0);
    float yv = hv * hv < 1.0f - 1e-6f ? hv * dd / sqrt(1.0f - hv * hv) : y1;
    float3 to_y = xu * ex + yv * ey + z0 * ez;
    float dist = length(to_y);
    s->dir = to_y / dist;
    s->dist = Ray_shadow_length(dist, x + to_y);
    /* one-sided: x must lie on the emitting side */
    bool front = dot(x - l->position.xyz, l->direction.xyz) > 0.0f;
    s->value = front ? l->radiance.xyz * (fmax(0.0f, dot(n, s->dir)) * solid) : (float3)(0.0f);
    return true;
}

/* Area light: rectangles by solid angle where it is large enough; else a
 * uniform point on the rectangle or ellipse, where radiance P/(pi A) times
 * the Jacobian A cos_y / t^2 gives P cos_x cos_y / (pi t^2). */
inline LightSample Light_sample_area(const Light *l, float3 x, float3 n, float u1, float u2) {
    LightSample s;
    if (l->shape == AREA_RECTANGLE && Light_sample_rect_solid_angle(l, x, n, u1, u2, &s)) return s;
    float2 q = l->shape == AREA_ELLIPSE ? 0.5f * Sampling_disk(u1, u2) : (float2)(u1 - 0.5f, u2 - 0.5f);
    float3 y = l->position.xyz + q.x * l->axis_u.xyz + q.y * l->axis_v.xyz;
    float3 to_y = y - x;
    float dist = length(to_y);
    if (!(dist > 0.0f)) return Light_none();
    s.dir = to_y / dist;
    s.dist = Ray_shadow_length(dist, y);
    float cos_x = fmax(0.0f, dot(n, s.dir));
    float cos_y = fmax(0.0f, -dot(l->direction.xyz, s.dir));
    s.value = l->power.xyz * (cos_x * cos_y / (PI_F * fmax(dist * dist, 1e-30f)));
    return s;
}

/* Emissive triangles: pick one by power, then a uniform point on it. */
inline LightSample Light_sample_mesh(const Emitters *em, float3 x, float3 n, float u0, float u1, float u2) {
    if (em->count <= 0) return Light_none();
    int lo = 0, hi = em->count - 1;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (em->cdf[mid] <= u0) lo = mid + 1; else hi = mid;
    }
    float prev = lo > 0 ? em->cdf[lo - 1] : 0.0f;
    float pick = em->cdf[lo] - prev;
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
    float cos_x = fmax(0.0f, dot(n, s.dir));
    float cos_y = fabs(dot(cr / len_cr, s.dir));
    float3 le = em->materials[em->tri_material[tri]].emission.xyz;
    s.value = le * (cos_x * cos_y * (0.5f * len_cr) / (fmax(dist * dist, 1e-30f) * pick));
    return s;
}

/* Uniform world of radiance L: cosine sampling gives the estimate pi L. */
inline LightSample Light_sample_world(float3 world, float3 n, float u1, float u2) {
    LightSample s;
    s.dir = Sampling_cosine(n, u1, u2);
    s.dist = LIGHT_FAR;
    s.value = PI_F * world;
    return s;
}

/* One sample of light l (sun, point, spot, area, mesh). */
inline LightSample Light_sample(const Light *l, const Emitters *em, float3 x, float3 n, float u0, float u1, float u2) {
    if (l->kind == LIGHT_SUN) return Light_sample_sun(l, n, u1, u2);
    if (l->kind == LIGHT_AREA) return Light_sample_area(l, x, n, u1, u2);
    if (l->kind == LIGHT_MESH) return Light_sample_mesh(em, x, n, u0, u1, u2);
    return Light_sample_point(l, x, n, u1, u2);
}

/* Radiance a ray (org, dir) sees on a point, spot or area light closer than
 * tmax; zero when it misses. Area lights show only their emitting side;
 * point and spot lights show their disk facing the ray origin. */
inline float3 Light_seen(const Light *l, float3 org, float3 dir, float tmax) {
    float3 none = (float3)(0.0f);
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
    if (!(t > 0.0f && t < tmax)) return none;
    float3 q = org + t * dir - c;
    if (l->kind == LIGHT_AREA) {
        float a = dot(q, l->axis_u.xyz) / dot(l->axis_u.xyz, l->axis_u.xyz);
        float b = dot(q, l->axis_v.xyz) / dot(l->axis_v.xyz, l->axis_v.xyz);
        bool inside = l->shape == AREA_ELLIPSE ? (a * a + b * b <= 0.25f) : (fabs(a) <= 0.5f && fabs(b) <= 0.5f);
        return inside ? l->radiance.xyz : none;
    }
    if (dot(q, q) > l->radius * l->radius) return none;
    float atten = l->kind == LIGHT_SPOT ? Light_spot_attenuation(l, -dir) : 1.0f;
    return l->radiance.xyz * atten;
}

/* Radiance an escaping ray sees on a sun's disk. */
inline float3 Light_sun_seen(const Light *l, float3 dir) {
    if (l->kind != LIGHT_SUN || !(l->cos_half < 1.0f)) return (float3)(0.0f);
    return dot(dir, -l->direction.xyz) >= l->cos_half ? l->radiance.xyz : (float3)(0.0f);
}

#endif
