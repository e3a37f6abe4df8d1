/* Offsets of secondary rays. float32 hit points carry a rounding error that
 * grows with the size of the coordinates involved, so every offset is
 * relative to those coordinates, never an absolute constant: the same scene
 * renders alike at any scale and far from the origin (positions arrive
 * recentred on the scene). */
#ifndef GPUGI_RAY_H
#define GPUGI_RAY_H

/* Offset per unit of coordinate magnitude: about 170 float32 ulps. */
#define RAY_EPS_REL 2e-5f
/* Shadow rays stop this fraction short of the light point they aim at. */
#define RAY_SHADOW_SHORTEN 1e-4f
/* Upper end of an unbounded ray. */
#define RAY_FAR 3.0e38f

/* Largest absolute coordinate of p. */
inline float Ray_magnitude(float3 p) {
    return fmax(fmax(fabs(p.x), fabs(p.y)), fabs(p.z));
}

/* Offset for a point computed from coordinates of magnitude up to `mag`. */
inline float Ray_offset(float mag) {
    return RAY_EPS_REL * mag;
}

/* Length of a shadow ray towards light point y at distance d, stopping
 * short of y by its own rounding error and a small fraction of d. */
inline float Ray_shadow_length(float d, float3 y) {
    return d * (1.0f - RAY_SHADOW_SHORTEN) - Ray_offset(Ray_magnitude(y));
}

#endif
