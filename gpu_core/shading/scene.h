/* The scene as every path-following kernel reads it: one argument bundle
 * (SCENE_PARAMS, host: SceneBuffers.kernel_args()) and a view of it
 * (SceneView) that shading functions take instead of a dozen pointers. */
#ifndef GPUGI_SCENE_H
#define GPUGI_SCENE_H
#include "accel/kdtree_traverse.h"
#include "shading/lights.h"

#define SCENE_PARAMS                                                                              \
    KDTREE_PARAMS, const __global float4 *sc_normals, const __global float2 *sc_uvs,              \
        const __global float4 *sc_tangents,                                                      \
        const __global int *sc_material_of, const __global Material *sc_materials,               \
        const __global float4 *sc_atlas, const __global TextureInfo *sc_textures,                \
        const __global Light *sc_lights, const int sc_light_count, const __global int *sc_emit_tris, \
        const __global float *sc_emit_cdf, const int sc_emit_count, const __global Camera *sc_camera, \
        const float4 sc_world

typedef struct {
    KdTree tree;
    const __global float4 *normals;   /* 3 corner normals per triangle */
    const __global float2 *uvs;       /* 3 corner uvs per triangle */
    const __global float4 *tangents;  /* 3 corner tangents per triangle (SCENE_HAS_TANGENTS), w: bitangent sign */
    const __global int *material_of;  /* material row of each triangle */
    const __global Material *materials;
    const __global float4 *atlas;     /* every texture's texels */
    const __global TextureInfo *textures;
    const __global Light *lights;
    int light_count;
    Emitters em;                      /* emissive triangles, one light row of kind LIGHT_MESH */
    const __global Camera *camera;
    float4 world;                     /* rgb radiance of the world; w = 1 with a transparent film */
} SceneView;

#define SCENE_MAKE()                                                                              \
    ((SceneView){KDTREE_MAKE(), sc_normals, sc_uvs, sc_tangents, sc_material_of, sc_materials, sc_atlas,       \
                 sc_textures, sc_lights, sc_light_count,                                          \
                 {sc_emit_tris, sc_emit_cdf, sc_emit_count, kd_verts, sc_material_of, sc_materials}, \
                 sc_camera, sc_world})

/* Whether the world emits light. */
inline bool Scene_has_world(const SceneView *sc) {
    return sc->world.x > 0.0f || sc->world.y > 0.0f || sc->world.z > 0.0f;
}

#endif
