"""The viewport worker and an F12 render share one device: rendering at
once, many times, gives the images they give one after the other."""

from __future__ import annotations

import threading

import numpy as np
from scenes_py import camera_looking_down, make_scene, quad

from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_POINT, Lights, Materials
from gpu_core.settings import RenderSettings

GI = RenderSettings(mode="gi", samples=2, global_photons=20_000, caustic_photons=20_000, photon_k=20,
                    cache_seeds=80, gather_rays=16)
REFERENCE = RenderSettings(samples=4, diffuse_bounces=2)
ROUNDS = 4


def scene(mirror: bool, size: int):
    faces = [quad((0, 0, -1), 2), quad((0, 0, 1), 2, flip=True), quad((0, -1, 0), 2, normal_axis=1),
             quad((0, 1, 0), 2, normal_axis=1, flip=True), quad((-1, 0, 0), 2, normal_axis=0),
             quad((1, 0, 0), 2, normal_axis=0, flip=True)]
    ids, mats = [0] * 12, [dict(base_color=(0.5,) * 3)]
    if mirror:
        faces.append(quad((0.5, 0, -0.98), 0.6))
        ids += [1, 1]
        mats.append(dict(base_color=(0.9,) * 3, metallic=1.0, roughness=0.0))
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0.2, 0.1, 0.5), power=(100,) * 3)])
    camera = camera_looking_down(height=0.9, half_width=1.0, size=size)
    camera.clip_start, camera.clip_end = 1e-3, 20.0
    return make_scene(np.concatenate(faces), np.array(ids, np.int32), Materials.make(mats), lights, camera)


def test_two_renderers_on_one_device_at_once_give_their_sequential_images(device):
    jobs = {"viewport": (scene(True, 20), GI), "final": (scene(False, 24), REFERENCE)}
    expected = {name: Renderer(device).render(s, settings).passes["Combined"] for name, (s, settings) in jobs.items()}
    got = {name: [] for name in jobs}
    errors = []

    def work(name):
        s, settings = jobs[name]
        try:
            for _ in range(ROUNDS):
                got[name].append(Renderer(device).render(s, settings).passes["Combined"])
        except Exception as err:  # reported below, with the thread's name
            errors.append((name, err))

    threads = [threading.Thread(target=work, args=(name,)) for name in jobs]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=600)
    assert not errors and not any(t.is_alive() for t in threads)
    for name in jobs:
        assert len(got[name]) == ROUNDS
        assert all(np.array_equal(image, expected[name]) for image in got[name]), name
