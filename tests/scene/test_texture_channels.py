"""The values a value socket reads from an image texture (model.texture_channel)."""

import os
import time

import numpy as np
import pytest
from conftest import other_threads_cpu_ms

from gpu_core.scene import TEXTURE_LUMINANCE
from gpu_core.scene.model import LUMINANCE_WEIGHTS, texture_channel


def test_a_channel_is_read_as_is_and_luminance_is_the_rec709_weighted_sum():
    pixels = np.random.default_rng(2).random((5, 7, 4), dtype=np.float32)
    for channel in range(4):
        np.testing.assert_array_equal(texture_channel(pixels, channel), pixels[..., channel])
    np.testing.assert_array_equal(texture_channel(pixels, 9), pixels[..., 3])  # clamped to alpha
    expected = pixels[..., :3].astype(np.float64) @ np.array(LUMINANCE_WEIGHTS)
    luminance = texture_channel(pixels, TEXTURE_LUMINANCE)
    assert luminance.dtype == np.float32 and luminance.shape == (5, 7)
    np.testing.assert_allclose(luminance, expected, rtol=1e-6)


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="threads' CPU times are read from /proc")
def test_the_luminance_of_a_wide_texture_leaves_numpys_blas_threads_idle():
    # a matrix-vector product this wide goes to OpenBLAS's threads, which then
    # spin for about 0.1 s beside the render's kernels
    pixels = np.random.default_rng(3).random((2048, 4096, 4), dtype=np.float32)
    time.sleep(0.3)
    before = other_threads_cpu_ms()
    texture_channel(pixels, TEXTURE_LUMINANCE)
    time.sleep(0.3)  # a woken worker spins through this
    assert other_threads_cpu_ms() - before < 40
