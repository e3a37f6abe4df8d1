"""Small gpu_core scenes built in numpy, shared by the kernel and render tests."""

from __future__ import annotations

import numpy as np

from gpu_core.scene import CAMERA_ORTHO, CAMERA_PERSP, LIGHT_POINT, Camera, Lights, Materials, Scene


def quad(center, size, normal_axis=2, flip=False) -> np.ndarray:
    """Two triangles of an axis-aligned square facing +axis (or -axis if flip)."""
    c = np.asarray(center, np.float64)
    h = 0.5 * size
    a, b = [ax for ax in range(3) if ax != normal_axis]
    corners = []
    for da, db in ((-h, -h), (h, -h), (h, h), (-h, h)):
        p = c.copy()
        p[a] += da
        p[b] += db
        corners.append(p)
    p0, p1, p2, p3 = corners
    tris = np.array([[p0, p1, p2], [p0, p2, p3]])
    # winding so the geometric normal points along +normal_axis
    n = np.cross(p1 - p0, p2 - p0)
    if (n[normal_axis] < 0) != flip:
        tris = tris[:, ::-1]
    return tris


def sphere(center, radius, rings=12, segments=24):
    """Triangles of a UV sphere, wound outwards."""
    theta = np.linspace(0, np.pi, rings + 1)
    phi = np.linspace(0, 2 * np.pi, segments + 1)
    p = np.stack([np.outer(np.sin(theta), np.cos(phi)), np.outer(np.sin(theta), np.sin(phi)),
                  np.outer(np.cos(theta), np.ones_like(phi))], axis=-1) * radius + center
    tris = []
    for i in range(rings):
        for j in range(segments):
            a, b, c, d = p[i, j], p[i + 1, j], p[i + 1, j + 1], p[i, j + 1]
            if i > 0:
                tris.append([a, b, d])
            if i < rings - 1:
                tris.append([b, c, d])
    return np.array(tris)


def camera_looking_down(height=4.0, half_width=1.0, size=32, ortho=False, center=(0.0, 0.0)) -> Camera:
    """A camera at (cx, cy, height) looking down -Z; the image covers
    [-half_width, half_width]^2 around the centre on the plane z = 0."""
    m = np.eye(4)
    m[:3, 3] = (center[0], center[1], height)
    if ortho:
        window = (-half_width, half_width, -half_width, half_width)
        kind = CAMERA_ORTHO
    else:
        s = half_width / height
        window = (-s, s, -s, s)
        kind = CAMERA_PERSP
    return Camera(matrix=m, window=window, width=size, height=size, kind=kind, clip_start=1e-3 * height, clip_end=100.0 * height)


def plane_scene(lights: Lights, camera: Camera | None = None, albedo=0.8, plane_size=40.0, world=(0, 0, 0),
                extra_tris=None, extra_materials=None) -> Scene:
    """A diffuse square plane on z = 0 facing +Z, plus optional extra triangles."""
    tris = quad((0, 0, 0), plane_size)
    mats = [{"base_color": (albedo, albedo, albedo), "name": "plane"}]
    ids = [0, 0]
    if extra_tris is not None:
        for tri_group, mat in zip(extra_tris, extra_materials):
            ids += [len(mats)] * len(tri_group)
            mats.append(mat)
            tris = np.concatenate([tris, tri_group])
    return make_scene(tris, np.array(ids, np.int32), Materials.make(mats), lights, camera or camera_looking_down(), world)


def make_scene(tris, material_ids, materials, lights, camera, world=(0, 0, 0)) -> Scene:
    """A Scene with face normals as corner normals and zero UVs."""
    tris = np.asarray(tris, np.float64).reshape(-1, 3, 3)
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    normals = np.repeat(n[:, None, :], 3, axis=1).astype(np.float32)
    return Scene(
        triangles=tris,
        normals=normals,
        uvs=np.zeros((len(tris), 3, 2), np.float32),
        material_ids=np.asarray(material_ids, np.int32),
        materials=materials,
        lights=lights,
        camera=camera,
        world_color=np.asarray(world, np.float32),
    )


def box_scene(albedo=0.5, power=100.0, size=2.0, offset=(0.0, 0.0, 0.0), mirror=False, light=True):
    """A closed cube seen from inside, a point light in it; optionally a
    mirror panel on the floor. ``offset`` moves everything."""
    h = size / 2
    faces = [quad((0, 0, -h), size), quad((0, 0, h), size, flip=True),
             quad((0, -h, 0), size, normal_axis=1), quad((0, h, 0), size, normal_axis=1, flip=True),
             quad((-h, 0, 0), size, normal_axis=0), quad((h, 0, 0), size, normal_axis=0, flip=True)]
    tris = np.concatenate(faces)
    ids = [0] * len(tris)
    mats = [dict(base_color=(albedo,) * 3)]
    if mirror:
        tris = np.concatenate([tris, quad((0.3 * size, 0, -h + 0.01 * size), 0.4 * size)])
        ids += [1, 1]
        mats.append(dict(base_color=(0.9,) * 3, metallic=1.0, roughness=0.0))
    tris = tris + np.asarray(offset)
    lights = [dict(kind=LIGHT_POINT, position=np.asarray((0.15, 0.1, 0.3)) * size + offset,
                   power=(power,) * 3)] if light else []
    camera = camera_looking_down(height=0.45 * size, half_width=0.5 * size, size=24,
                                 center=(offset[0], offset[1]))
    camera.matrix[2, 3] += offset[2]
    camera.clip_start, camera.clip_end = 1e-3 * size, 10 * size
    return make_scene(tris, np.array(ids, np.int32), Materials.make(mats), Lights.make(lights), camera)


def on_device(device, scene):
    """The validated ``scene`` and its device copy (SceneBuffers), as the
    renderer uploads it: what stage kernels read."""
    from gpu_core.scene import validate
    from gpu_core.scene.tables import scene_tables
    from gpu_core.scene.upload import upload

    scene = validate(scene)
    return scene, upload(device, scene, scene_tables(scene))
