/* Device-side types shared by every program. Each struct here has a numpy
 * dtype twin in gpu_core/layout.py; tests/test_layout.py checks sizes and
 * offsets on the device. float3 is 16 bytes, so host twins use float4. */
#ifndef GPUGI_TYPES_H
#define GPUGI_TYPES_H

/* One kd-tree node, 16 bytes, in preorder: the left child of an inner node
 * is the next node; `child` is the right child's index.
 * Inner: axis 0..2, split = plane position, count = 0.
 * Leaf:  axis 3, child = first slot in the leaf index list, count = size. */
typedef struct {
    float split;
    int axis;
    int child;
    int count;
} KdNode;

#define KD_LEAF 3

/* A closest hit: distance, triangle index (-1 on a miss), barycentrics. */
typedef struct {
    float t;
    int tri;
    float u;
    float v;
} Hit;

/* Kernel parameters every tracing kernel takes for the triangle kd-tree, in
 * this order (host: KdTree.kernel_args()). verts holds 3 float4 per
 * triangle (v0, v1, v2; w unused); bounds are the root box. */
#define KDTREE_PARAMS                                                        \
    const __global KdNode *kd_nodes, const __global int *kd_leaf_tris,       \
        const __global float4 *kd_verts, const float4 kd_bmin,               \
        const float4 kd_bmax

typedef struct {
    const __global KdNode *nodes;
    const __global int *leaf_tris;
    const __global float4 *verts;
    float3 bmin;
    float3 bmax;
} KdTree;

#define KDTREE_MAKE()                                                        \
    ((KdTree){kd_nodes, kd_leaf_tris, kd_verts, kd_bmin.xyz, kd_bmax.xyz})


/* A material row (64 bytes); see gpu_core/layout.py MATERIAL_DTYPE. */
typedef struct {
    float4 base_color; /* rgb; w = alpha */
    float4 emission;   /* rgb radiance (colour x strength) */
    float metallic;
    float roughness;
    float transmission;
    float ior;
    int texture; /* index into the texture table, -1 for none */
    int pad0, pad1, pad2;
} Material;

#define LIGHT_POINT 0
#define LIGHT_SPOT 1
#define LIGHT_SUN 2
#define LIGHT_AREA 3
#define LIGHT_MESH 4 /* emissive triangles, sampled as one light */

/* A light row (128 bytes); see gpu_core/layout.py LIGHT_DTYPE. Derived
 * values (radiance, normalisations) are computed on the host in float64. */
typedef struct {
    float4 position;   /* xyz (sun: unused) */
    float4 direction;  /* xyz unit: where it shines, the light's -Z */
    float4 axis_u;     /* area: full size along the light's X */
    float4 axis_v;     /* area: full size along the light's Y */
    float4 power;      /* rgb: watts (sun: W/m^2) */
    float4 radiance;   /* rgb radiance a ray sees on the light; 0 = not visible */
    float radius;      /* point, spot: radius of the disk facing the receiver */
    float cos_half;    /* spot: cos of half the cone; sun: cos of half the disk */
    float spot_smooth; /* spot: 1 / ((1 - cos_half) * blend), smoothstep scale */
    float sun_norm;    /* sun: 2 / (1 + cos_half), so the disk gives S at normal incidence */
    int kind;
    int shape; /* area: 0 rectangle, 1 ellipse */
    int pad0, pad1;
} Light;

/* The camera (112 bytes); see gpu_core/layout.py CAMERA_DTYPE. */
typedef struct {
    float4 right;   /* camera X axis in world space */
    float4 up;      /* camera Y axis */
    float4 back;    /* camera Z axis (it looks down -Z) */
    float4 origin;  /* position */
    float4 window;  /* x0, x1, y0, y1 on the plane z = -1 (ortho: scene units) */
    int kind;       /* 0 perspective, 1 orthographic */
    int width;      /* full image size in pixels */
    int height;
    int pad0;
    float clip_start;
    float clip_end;
    float pad1, pad2;
} Camera;

/* A texture's place in the shared float4 atlas. */
typedef struct {
    int offset;
    int width;
    int height;
    int pad0;
} TextureInfo;

#endif
