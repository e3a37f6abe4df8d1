"""Rendered viewport without a window: pixel preparation drawn with moderngl,
the worker scheduler with a fake renderer, the view camera from fake contexts."""

from __future__ import annotations

import dataclasses
import itertools
import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest

from blender_addon.display import DISPLAY_MAX, prepare_pixels
from blender_addon.engine import GpuGiRenderEngine
from blender_addon.viewport import (BATCH_SECONDS, COARSE_FACTOR, OPEN_MIN_SAMPLES, UNSETTLED_WARM_SAMPLES, Job,
                                   ViewportSession, pass_settings, passes, view_state)
from gpu_core.device import get_device
from gpu_core.scene import FILTER_BLACKMAN_HARRIS, FILTER_BOX
from gpu_core.errors import DeviceError, RenderCancelled
from gpu_core.scene import CAMERA_ORTHO, CAMERA_PERSP, Lights
from gpu_core.settings import RenderSettings
from scenes_py import camera_looking_down, plane_scene

# -- pixels ---------------------------------------------------------------------


def test_prepare_pixels_clamps_and_removes_non_finite_values():
    img = np.array([[[np.nan, np.inf, -np.inf, 2.0], [-1.0, 1e9, 0.5, 1.0]]], np.float32)
    out = prepare_pixels(img, 2, 1)
    np.testing.assert_array_equal(out, [[[0.0, DISPLAY_MAX, 0.0, 2.0], [0.0, DISPLAY_MAX, 0.5, 1.0]]])
    assert out.dtype == np.float32 and out.flags["C_CONTIGUOUS"]


def test_prepare_pixels_scales_a_coarse_image_by_nearest_neighbour_keeping_rows_bottom_up():
    coarse = np.zeros((2, 3, 4), np.float32)
    coarse[..., 0] = np.arange(6).reshape(2, 3)  # row 0 is the bottom row
    out = prepare_pixels(coarse, 6, 4)
    assert out.shape == (4, 6, 4)
    np.testing.assert_array_equal(out[..., 0], np.repeat(np.repeat(coarse[..., 0], 2, axis=0), 2, axis=1))


def test_prepare_pixels_rejects_images_without_four_channels():
    with pytest.raises(ValueError):
        prepare_pixels(np.zeros((4, 4, 3), np.float32), 4, 4)


_VERTEX = """
#version 330
in vec2 pos;
out vec2 uv;
void main() { uv = pos * 0.5 + 0.5; gl_Position = vec4(pos, 0.0, 1.0); }
"""
_FRAGMENT = """
#version 330
uniform sampler2D image;
in vec2 uv;
out vec4 color;
void main() { color = texture(image, uv); }
"""


def test_prepared_pixels_draw_unchanged_on_a_float_framebuffer():
    moderngl = pytest.importorskip("moderngl")
    # Mesa's EGL driver loads its own LLVM (15): a process that loads it before
    # PoCL's aborts at its first OpenCL build, so the OpenCL device comes first
    get_device(None)
    ctx = moderngl.create_standalone_context(backend="egl")
    try:
        width, height = 24, 16
        rng = np.random.default_rng(1)
        coarse = (rng.random((height // 4, width // 4, 4)) * 3.0).astype(np.float32)
        coarse[0, 0] = (1e6, np.nan, 0.25, 1.0)  # bottom-left: clamped and cleaned
        pixels = prepare_pixels(coarse, width, height)
        # the upload Blender's viewport does: a width x height RGBA32F texture, rows from the bottom
        texture = ctx.texture((width, height), 4, pixels.tobytes(), dtype="f4")
        texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        target = ctx.framebuffer(color_attachments=[ctx.texture((width, height), 4, dtype="f4")])
        program = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        quad = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], np.float32).tobytes())
        vao = ctx.vertex_array(program, [(quad, "2f", "pos")])
        target.use()
        texture.use(0)
        vao.render(moderngl.TRIANGLE_STRIP)
        drawn = np.frombuffer(target.read(components=4, dtype="f4"), np.float32).reshape(height, width, 4)
    finally:
        ctx.release()
    np.testing.assert_array_equal(drawn, pixels)  # read back bottom row first, like the texture
    np.testing.assert_array_equal(drawn[0, 0], (DISPLAY_MAX, 0.0, 0.25, 1.0))


# -- view camera ------------------------------------------------------------------


def _context(width, height, view, window, perspective=True):
    return SimpleNamespace(
        region=SimpleNamespace(width=width, height=height),
        region_data=SimpleNamespace(view_matrix=view, window_matrix=window, is_perspective=perspective),
        scene=SimpleNamespace(cycles=SimpleNamespace(pixel_filter_type="BLACKMAN_HARRIS", filter_width=1.5)),
    )


def _perspective(fx, fy, near, far, shift=(0.0, 0.0)):
    p = np.zeros((4, 4))
    p[0, 0], p[1, 1], p[0, 2], p[1, 2] = fx, fy, shift[0], shift[1]
    p[2, 2], p[2, 3], p[3, 2] = -(far + near) / (far - near), -2 * far * near / (far - near), -1.0
    return p


def _orthographic(sx, sy, near, far):
    p = np.eye(4)
    p[0, 0], p[1, 1] = sx, sy
    p[2, 2], p[2, 3] = -2.0 / (far - near), -(far + near) / (far - near)
    return p


def test_view_camera_from_a_perspective_viewport():
    view = np.eye(4)
    view[:3, 3] = (0.0, 0.0, -10.0)  # the eye at z = +10 looking down -Z
    state = view_state(_context(80, 40, view, _perspective(2.0, 4.0, 0.1, 100.0, shift=(0.2, -0.4))))
    cam = state.camera
    assert cam.kind == CAMERA_PERSP and (cam.width, cam.height) == (80, 40)
    np.testing.assert_allclose(cam.matrix[:3, 3], (0, 0, 10))
    # at z = -1: x_ndc = 2 x - 0.2 and y_ndc = 4 y + 0.4
    np.testing.assert_allclose(cam.window, (-0.4, 0.6, -0.35, 0.15), atol=1e-12)
    assert (cam.clip_start, cam.clip_end) == pytest.approx((0.1, 100.0))


def test_orthographic_viewport_that_clips_behind_its_eye_is_moved_back():
    view = np.eye(4)
    state = view_state(_context(50, 50, view, _orthographic(0.5, 0.5, -20.0, 20.0), perspective=False))
    cam = state.camera
    assert cam.kind == CAMERA_ORTHO
    np.testing.assert_allclose(cam.window, (-2, 2, -2, 2))
    np.testing.assert_allclose(cam.matrix[:3, 3], (0, 0, 20))  # moved back along +Z by the negative near
    assert (cam.clip_start, cam.clip_end) == pytest.approx((0.0, 40.0))


def test_view_signature_changes_with_region_size_and_matrices():
    view, window = np.eye(4), _perspective(1.0, 1.0, 0.1, 10.0)
    base = view_state(_context(10, 10, view, window)).signature
    assert view_state(_context(10, 10, view.copy(), window.copy())).signature == base
    assert view_state(_context(11, 10, view, window)).signature != base
    moved = view.copy()
    moved[0, 3] = 0.5
    assert view_state(_context(10, 10, moved, window)).signature != base


def test_the_view_camera_takes_the_film_filter_and_a_filter_edit_changes_the_signature():
    view, window = np.eye(4), _perspective(1.0, 1.0, 0.1, 10.0)
    context = _context(10, 10, view, window)
    state = view_state(context)
    assert (state.camera.filter_kind, state.camera.filter_width) == (FILTER_BLACKMAN_HARRIS, 1.5)
    context.scene.cycles.pixel_filter_type = "BOX"
    boxed = view_state(context)
    assert boxed.camera.filter_kind == FILTER_BOX and boxed.signature != state.signature


# -- worker scheduling --------------------------------------------------------------


class FakeRenderer:
    """Records each render; ``block`` makes a render wait until it is asked
    to stop. The image of the n-th render is n everywhere; an accumulating
    render reports its film holding every sample from 0 to its last, all
    pixels taking them, settled from ``settle_at`` samples on."""

    def __init__(self, block=False, error=None, linger=0.0, settle_at=None):
        self.settle_at = settle_at
        self.accumulating: list[bool] = []
        self.thresholds: list[float] = []
        self.calls: list[tuple[int, int, int]] = []
        self.linger = linger  # seconds a render takes to end, cancelled or not
        self.active = self.most_at_once = 0
        self.starts: list[int] = []
        self.edits: list = []
        self.denoised: list[bool] = []
        self.guides: list[bool] = []
        self.block = block
        self.error = error
        self.started = threading.Event()

    def render(self, scene, settings, progress=None, should_stop=None, edits=None, sample_start=0, accumulate=False):
        cam = scene.camera
        self.accumulating.append(accumulate)
        self.thresholds.append(settings.noise_threshold)
        self.calls.append((cam.width, cam.height, settings.samples))
        self.starts.append(sample_start)
        self.edits.append(edits)
        self.denoised.append(settings.denoise)
        self.guides.append(settings.denoising_passes)
        self.started.set()
        if self.error is not None:
            raise self.error
        self.active += 1
        self.most_at_once = max(self.most_at_once, self.active)
        try:
            while self.block:
                if should_stop():
                    raise RenderCancelled("render cancelled")
                time.sleep(0.005)
            time.sleep(self.linger)
        finally:
            self.active -= 1
        image = np.full((cam.height, cam.width, 4), float(len(self.calls)), np.float32)
        passes = {"Combined": image}
        if settings.denoising_passes:
            passes["Denoising Albedo"] = np.full((cam.height, cam.width, 3), 0.5, np.float32)
            passes["Denoising Normal"] = np.zeros((cam.height, cam.width, 3), np.float32)
            passes["Denoising Normal"][..., 2] = 1.0
        stats = {"triangles": 2}
        if accumulate:
            held = sample_start + settings.samples
            settled = self.settle_at is not None and held >= self.settle_at
            stats["accumulated"] = {"samples": held, "mean_samples": held / 2 if settled else held,
                                    "converged": settled, "sample_start": 0}
        return SimpleNamespace(passes=passes, stats=stats, warnings=[])


def _job(width=64, height=32, samples=8, pixel_size=1, denoise=False, edits=None):
    camera = dataclasses.replace(camera_looking_down(), width=width, height=height)
    return Job(scene=plane_scene(Lights.make([]), camera), settings=RenderSettings(samples=samples, denoise=denoise),
               device_spec=None, pixel_size=pixel_size, edits=edits)


def _session(renderer):
    redraws = []
    session = ViewportSession(lambda: redraws.append(1), make_renderer=lambda spec: renderer)
    return session, redraws


def _wait(session):
    deadline = time.time() + 10
    while session.busy and time.time() < deadline:
        time.sleep(0.005)
    assert not session.busy


def test_worker_renders_coarse_then_accumulates_full_passes_up_to_the_viewport_samples():
    renderer = FakeRenderer()
    session, redraws = _session(renderer)
    session.update_scene(_job(samples=8), signature=("view", 1))
    _wait(session)
    coarse = (64 // COARSE_FACTOR, 32 // COARSE_FACTOR, 1)
    assert renderer.calls == [coarse, (64, 32, 1), (64, 32, 2), (64, 32, 4), (64, 32, 1)]
    assert renderer.starts == [0, 0, 1, 3, 7]  # the full passes number their samples on from each other
    assert renderer.accumulating == [False, True, True, True, True]  # each full pass continues the film
    image, version = session.latest()
    # the film after the last pass, as the renderer holds it (the n-th render's image is n)
    np.testing.assert_allclose(image, 5.0)
    assert image.shape == (32, 64, 4) and version == 5 and len(redraws) == 5
    assert session.samples == 8 and session.status.endswith("sample 8/8, 2 triangles")
    assert session.error is None


def test_pass_schedule_doubles_up_to_its_cap_and_never_ends_at_zero_samples():
    counts = [step.samples for step in itertools.islice(passes(_job(samples=0)), 8)]
    assert counts == [1, 1, 2, 4, 8, 16, 16, 16]
    assert sum(step.samples for step in passes(_job(samples=100)) if not step.coarse) == 100


def test_every_viewport_pass_launches_the_image_in_shorter_batches_than_f12():
    job = _job(samples=4)
    assert all(pass_settings(job.settings, step).batch_seconds == BATCH_SECONDS for step in passes(job))
    assert BATCH_SECONDS < RenderSettings().batch_seconds


def test_full_passes_judge_noise_by_the_viewport_threshold_after_a_quarter_of_the_viewport_samples():
    job = _job(samples=64)
    job = dataclasses.replace(job, settings=dataclasses.replace(job.settings, noise_threshold=0.01,
                                                                preview_noise_threshold=0.05))
    steps = list(passes(job))
    chosen = [pass_settings(job.settings, step) for step in steps]
    assert [s.noise_threshold for s in chosen] == [0.0] + [0.05] * (len(steps) - 1)  # the coarse pass: none
    assert {s.min_samples for s in chosen} == {16}
    open_ended = dataclasses.replace(job, settings=dataclasses.replace(job.settings, samples=0))
    assert pass_settings(open_ended.settings, steps[1]).min_samples == OPEN_MIN_SAMPLES
    chosen_min = dataclasses.replace(job.settings, min_samples=6)
    assert pass_settings(chosen_min, steps[1]).min_samples == 6
    assert not any(s.geometry_passes for s in chosen)  # the viewport shows Combined: no Depth or Normal read back


@pytest.mark.parametrize("denoise", [False, True])
def test_a_view_whose_pixels_have_all_settled_stops_before_its_samples_and_is_denoised_then(denoise):
    renderer = FakeRenderer(settle_at=8)
    session, _ = _session(renderer)
    session.update_scene(_job(samples=64, denoise=denoise), signature=("view", 1))
    _wait(session)
    assert [samples for _, _, samples in renderer.calls] == [1, 1, 2, 4, 8]  # settled after the pass to 15
    assert session.samples == 15
    label = "sample 15/64 (7.5 per pixel), settled" + (", denoised" if denoise else "")
    assert session.status.endswith(label + ", 2 triangles")


@pytest.mark.parametrize("denoise", [False, True])
def test_only_the_accumulated_full_image_is_denoised_and_only_when_asked(denoise):
    renderer = FakeRenderer()
    session, _ = _session(renderer)
    session.update_scene(_job(samples=4, denoise=denoise), signature=("view", 1))
    _wait(session)
    assert renderer.denoised == [False] * 4  # the renderer never denoises a pass; the session does, at the end
    assert renderer.guides == [False] + [denoise] * 3
    assert session.status.endswith("sample 4/4, denoised, 2 triangles" if denoise else "sample 4/4, 2 triangles")


def test_edits_reach_the_first_render_only_and_a_cancelled_job_passes_its_edits_on():
    renderer = FakeRenderer(block=True)
    session, _ = _session(renderer)
    session.update_scene(_job(edits={"geometry"}), signature=("view", 1))
    assert renderer.started.wait(5)
    renderer.block = False
    session.update_scene(_job(edits={"lights"}), signature=("view", 1))
    _wait(session)
    # the first job's render took its edits; the second's first render the new ones
    assert renderer.edits[0] == {"geometry"} and renderer.edits[1] == {"lights"}
    assert all(edits == set() for edits in renderer.edits[2:])
    unknown = FakeRenderer()
    session, _ = _session(unknown)
    session.update_scene(_job(edits=None), signature=("view", 1))
    _wait(session)
    assert unknown.edits[0] is None  # not known: the renderer compares every part


def test_a_sync_that_changed_nothing_does_not_restart():
    renderer = FakeRenderer()
    session, _ = _session(renderer)
    assert session.update_scene(_job(edits=None), signature=("view", 1))
    _wait(session)
    calls = len(renderer.calls)
    assert not session.update_scene(_job(edits=set()), signature=("view", 1))
    assert session.update_scene(_job(edits=set(), samples=16), signature=("view", 1))  # a setting changed
    _wait(session)
    assert len(renderer.calls) > calls


def test_pixel_size_preference_divides_the_full_resolution():
    renderer = FakeRenderer()
    session, _ = _session(renderer)
    session.update_scene(_job(pixel_size=2), signature=("view", 1))
    _wait(session)
    assert renderer.calls[-1][:2] == (32, 16)


def test_same_view_does_not_restart_and_a_new_view_does():
    renderer = FakeRenderer()
    session, _ = _session(renderer)
    session.update_scene(_job(), signature=("view", 1))
    _wait(session)
    same = SimpleNamespace(signature=("view", 1), camera=None)
    assert session.update_view(same) is False
    moved_cam = dataclasses.replace(session.job.scene.camera, width=40, height=20)
    assert session.update_view(SimpleNamespace(signature=("view", 2), camera=moved_cam)) is True
    _wait(session)
    assert renderer.calls[-1][:2] == (40, 20) and session.samples == 8


def test_an_edit_stops_the_running_render_without_waiting_and_the_next_job_waits_for_it():
    renderer = FakeRenderer(block=True, linger=0.5)
    session, _ = _session(renderer)
    session.update_scene(_job(), signature=("view", 1))
    assert renderer.started.wait(5)
    session.update_scene(_job(width=16, height=16), signature=("view", 2))
    assert renderer.active == 1  # Blender's thread did not wait for the stopped render's batch
    renderer.block = False
    _wait(session)
    assert renderer.most_at_once == 1  # never two renders at once
    assert renderer.calls[-1][:2] == (16, 16) and session.samples == 8
    assert session.error is None


def test_stop_ends_a_blocked_worker():
    renderer = FakeRenderer(block=True)
    session, _ = _session(renderer)
    session.update_scene(_job(), signature=("view", 1))
    assert renderer.started.wait(5)
    session.stop()
    assert not session.busy and session.latest()[0] is None


def test_worker_errors_become_messages_not_exceptions():
    renderer = FakeRenderer(error=DeviceError("no OpenCL device"))
    session, redraws = _session(renderer)
    session.update_scene(_job(), signature=("view", 1))
    _wait(session)
    assert session.error == "no OpenCL device" and "no OpenCL device" in session.status
    assert redraws
    broken = FakeRenderer(error=KeyError("x"))
    session, _ = _session(broken)
    session.update_scene(_job(), signature=("view", 1))
    _wait(session)
    assert session.error.startswith("internal error (KeyError)")


def test_a_gone_engine_stops_the_worker_quietly():
    def redraw():
        raise ReferenceError("StructRNA of type GpuGiRenderEngine has been removed")

    renderer = FakeRenderer()
    session = ViewportSession(redraw, make_renderer=lambda spec: renderer)
    session.update_scene(_job(), signature=("view", 1))
    _wait(session)
    assert len(renderer.calls) == 1  # the full pass never started
    assert session.error is None
    session._thread.join(5)
    assert not session._thread.is_alive()  # and the worker ended


def test_one_worker_thread_serves_every_edit_of_a_session():
    renderer = FakeRenderer()
    session, _ = _session(renderer)
    workers = set()
    for width in range(20, 30):
        session.update_scene(_job(width=width), signature=("view", width))
        workers.add(session._thread)
    _wait(session)
    assert len(workers) == 1 and renderer.calls[-1][0] == 29
    worker = session._thread
    session.stop()
    assert not worker.is_alive()


# -- the edit kernels' warm-up on the idle worker ---------------------------------------


class FakeWarmUp:
    """Records each warm-up; ``block`` makes the first wait until told to stop."""

    def __init__(self, block=False):
        self.jobs: list = []
        self.stopped: list[bool] = []
        self.block = block
        self.started = threading.Event()

    def __call__(self, job, should_stop):
        self.jobs.append(job)
        self.started.set()
        deadline = time.time() + 10
        while self.block and not should_stop() and time.time() < deadline:
            time.sleep(0.005)
        self.block = False
        self.stopped.append(should_stop())


def _warming_session(renderer, warm_up):
    return ViewportSession(lambda: None, make_renderer=lambda spec: renderer, warm_up=warm_up)


def _wait_idle(session):
    deadline = time.time() + 10
    while (session.busy or session.warming) and time.time() < deadline:
        time.sleep(0.005)
    assert not session.busy and not session.warming


def test_a_settled_view_warms_the_edit_kernels_on_the_idle_worker():
    renderer, warm_up = FakeRenderer(), FakeWarmUp()
    session = _warming_session(renderer, warm_up)
    job = _job(samples=4)
    session.update_scene(job, signature=("view", 1))
    _wait_idle(session)
    assert warm_up.jobs == [job] and warm_up.stopped == [False]  # after the last pass, nothing waiting
    assert len(renderer.calls) == 4


def test_a_view_stopped_before_it_settled_does_not_warm_up():
    renderer, warm_up = FakeRenderer(block=True), FakeWarmUp()
    session = _warming_session(renderer, warm_up)
    session.update_scene(_job(width=32), signature=("view", 1))
    assert renderer.started.wait(5)
    session.update_scene(_job(width=16, samples=2), signature=("view", 2))
    renderer.block = False
    _wait_idle(session)
    assert [job.scene.camera.width for job in warm_up.jobs] == [16]  # only the view that settled


def test_a_view_that_never_settles_warms_up_once_between_its_passes_and_goes_on():
    # Viewport Samples 0 and no noise threshold: the view never settles, so it
    # pauses once it holds as many samples as the default view settles with
    renderer, held_at_warm_up = FakeRenderer(), []

    def warm_up(job, should_stop):
        held_at_warm_up.append(renderer.starts[-1] + renderer.calls[-1][2])

    session = _warming_session(renderer, warm_up)
    session.update_scene(_job(samples=0), signature=("view", 1))
    deadline = time.time() + 10
    while len(renderer.calls) < 12 and time.time() < deadline:
        time.sleep(0.005)
    session.stop()
    assert len(renderer.calls) >= 12  # passes went on after the warm-up
    assert held_at_warm_up == [47]  # once: after the first pass to reach 32 samples (1 + 2 + 4 + 8 + 16 + 16)
    assert UNSETTLED_WARM_SAMPLES == 32 == RenderSettings().preview_samples


def test_closing_the_view_does_not_wait_for_a_warm_up_stage():
    # a stage of the warm-up may be a program's compile: Blender's thread must not wait for it
    release, inside, ended = threading.Event(), threading.Event(), threading.Event()

    def compiling(job, should_stop):
        inside.set()
        release.wait(10)
        ended.set()

    session = _warming_session(FakeRenderer(), compiling)
    session.update_scene(_job(samples=2), signature=("view", 1))
    assert inside.wait(5)
    closing = threading.Thread(target=session.stop)
    closing.start()
    closing.join(5)
    try:
        assert not closing.is_alive() and not ended.is_set()  # stop returned with the stage still running
    finally:
        release.set()
    assert ended.wait(5)


def test_an_edit_stops_the_warm_up_and_renders_at_once():
    renderer, warm_up = FakeRenderer(), FakeWarmUp(block=True)
    session = _warming_session(renderer, warm_up)
    session.update_scene(_job(samples=2), signature=("view", 1))
    assert warm_up.started.wait(5) and session.warming
    calls = len(renderer.calls)
    session.update_scene(_job(samples=2, edits={"lights"}), signature=("view", 2))
    _wait_idle(session)
    assert warm_up.stopped == [True, False]  # it saw the queued edit; the edited view warmed up in turn
    assert renderer.edits[calls] == {"lights"}  # the edit rendered after the first


# -- the engine's viewport callbacks, with a stand-in for Blender's engine struct ---------


class RecordingDrawer:
    """Takes the place of the gpu-module drawer (unavailable in background mode)."""

    def __init__(self):
        self.draws: list[tuple[np.ndarray, int, int, int]] = []

    def draw(self, engine, scene, image, version, width, height):
        self.draws.append((prepare_pixels(image, width, height), version, width, height))


class StandInEngine:
    """What view_update and view_draw use of the RenderEngine struct."""

    _report_viewport_error = vars(GpuGiRenderEngine)["_report_viewport_error"]

    def __init__(self):
        self._viewport = None
        self._sync = None
        self._drawer = RecordingDrawer()
        self._reported_error = None
        self.reports: list[tuple[set, str]] = []
        self.stats: list[str] = []

    def tag_redraw(self):
        pass

    def report(self, kind, message):
        self.reports.append((kind, message))

    def update_stats(self, stats, info):
        self.stats.append(info)

    def get_preview_pixel_size(self, scene):
        return 1


def _viewport_context(bpy, width, height, distance):
    """A 3D view looking down at the origin from ``distance``."""
    view = np.eye(4)
    view[2, 3] = -distance
    return _context(width, height, view, _perspective(1.5, 1.5 * width / height, 0.1, 100.0))


def test_engine_viewport_callbacks_render_and_follow_the_view(bpy_empty):
    bpy = bpy_empty
    bpy.ops.mesh.primitive_plane_add(size=20)
    bpy.ops.object.light_add(type="SUN")
    bpy.context.scene.gpugi.preview_samples = 2
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view_update, view_draw = vars(GpuGiRenderEngine)["view_update"], vars(GpuGiRenderEngine)["view_draw"]
    engine = StandInEngine()
    near = _viewport_context(bpy, 32, 24, 5.0)

    view_update(engine, near, depsgraph)
    assert not engine.reports
    _wait(engine._viewport)
    view_draw(engine, near, depsgraph)
    pixels, version, width, height = engine._drawer.draws[-1]
    assert (width, height) == (32, 24) and pixels.shape == (24, 32, 4) and version == 3
    assert np.isfinite(pixels).all() and pixels[..., :3].min() > 0  # the lit plane fills the view
    assert engine.stats[-1].startswith("GPU GI | gi | sample 2/2")  # GI is the add-on's default mode

    # orbiting only calls view_draw: a new view restarts the worker with the new camera
    far = _viewport_context(bpy, 40, 20, 50.0)
    view_draw(engine, far, depsgraph)
    _wait(engine._viewport)
    view_draw(engine, far, depsgraph)
    pixels, version, width, height = engine._drawer.draws[-1]
    assert (width, height) == (40, 20) and version == 6
    assert engine._viewport.job.scene.camera.width == 40
    engine._viewport.stop()


def test_engine_viewport_reports_errors_without_raising(bpy_empty):
    bpy = bpy_empty
    bpy.ops.mesh.primitive_plane_add()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view_update, view_draw = vars(GpuGiRenderEngine)["view_update"], vars(GpuGiRenderEngine)["view_draw"]
    engine = StandInEngine()
    # an error while exporting (a degenerate view) is reported at once
    view_update(engine, _context(10, 10, np.eye(4), np.zeros((4, 4))), depsgraph)
    assert engine.reports[-1] == ({"ERROR"}, "GPU GI: the view's projection is degenerate (zero-size view?)")
    # an error in the worker (a camera clipping nothing) is reported by the next draw, once
    clipped = _context(10, 10, np.eye(4), _perspective(1.0, 1.0, 5.0, 2.0))  # far in front of near
    view_update(engine, clipped, depsgraph)
    _wait(engine._viewport)
    view_draw(engine, clipped, depsgraph)
    view_draw(engine, clipped, depsgraph)
    errors = [message for kind, message in engine.reports[1:] if kind == {"ERROR"}]
    assert len(errors) == 1 and "clipping" in errors[0]
    assert engine.stats[-1].startswith("GPU GI | error")
