/* Camera rays through a pixel position of the full image. */
#ifndef GPUGI_CAMERA_H
#define GPUGI_CAMERA_H
#include "device/structs.h"

/* Ray through image position (px, py) in pixels (rows from the bottom);
 * writes origin, unit direction and the clipping interval along it. */
inline void Camera_ray(const Camera *c, float px, float py, float3 *org, float3 *dir, float *tmin, float *tmax) {
    float sx = c->window.x + (c->window.y - c->window.x) * (px / (float)c->width);
    float sy = c->window.z + (c->window.w - c->window.z) * (py / (float)c->height);
    float3 fwd = -c->back.xyz;
    if (c->kind == CAMERA_ORTHO) {
        *org = c->origin.xyz + sx * c->right.xyz + sy * c->up.xyz;
        *dir = fwd;
        *tmin = c->clip_start;
        *tmax = c->clip_end;
        return;
    }
    float3 d = sx * c->right.xyz + sy * c->up.xyz + fwd;
    float len = length(d);
    *org = c->origin.xyz;
    *dir = d / len;
    /* clipping planes are distances along the view axis */
    *tmin = c->clip_start * len;
    *tmax = c->clip_end * len;
}

/* Distance of p from the camera plane, like Cycles' Depth pass. */
inline float Camera_depth(const Camera *c, float3 p) {
    return dot(p - c->origin.xyz, -c->back.xyz);
}

#endif
