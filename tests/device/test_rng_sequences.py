"""The scrambled Sobol pairs of device/rng.h (the image kernel's light and
BSDF samples at a path's first smooth event): every aligned block of 2^m
points is a (0, m, 2)-net, whatever the seed, and seeds give independent
sequences."""

import os

import numpy as np
import pyopencl as cl
import pytest

from gpu_core.device.programs import INCLUDE_ROOT

_KERNEL = """
#include "device/rng.h"
__kernel void Rng_probe(const uint seed, __global float2 *out) {
    uint i = get_global_id(0);
    out[i] = Rng_sobol2(i, seed);
}
"""
COUNT = 1024


@pytest.fixture
def sobol(device, probe_program, tmp_path):
    """points(seed) -> (COUNT, 2) float32: Rng_sobol2 of indices 0..COUNT-1."""
    (tmp_path / "device").mkdir()
    with open(os.path.join(INCLUDE_ROOT, "device", "rng.h")) as f:
        (tmp_path / "device" / "rng.h").write_text(f.read())
    probe_program("rng_probe.cl", _KERNEL)
    kernel = cl.Kernel(device.program("rng_probe.cl"), "Rng_probe")

    def points(seed: int) -> np.ndarray:
        out = device.empty(8 * COUNT)
        kernel(device.queue, (COUNT,), None, np.uint32(seed), out)
        return device.read(out, 2 * COUNT, np.float32).reshape(COUNT, 2)

    return points


def _is_net(block: np.ndarray) -> bool:
    """Whether the 2^m points of ``block`` put one point in every cell of
    every 2^a x 2^(m-a) grid of the unit square."""
    m = int(np.log2(len(block)))
    for a in range(m + 1):
        x = np.floor(block[:, 0] * 2**a).astype(np.int64)
        y = np.floor(block[:, 1] * 2 ** (m - a)).astype(np.int64)
        if len(np.unique(x * 2 ** (m - a) + y)) != len(block):
            return False
    return True


@pytest.mark.parametrize("seed", [0, 1, 0x9E3779B9, 0xFFFFFFFF])
def test_sobol_pairs_fill_every_elementary_cell_once_per_aligned_block(sobol, seed):
    points = sobol(seed)
    assert ((points >= 0.0) & (points < 1.0)).all()
    for size in (4, 16, 64, 256, 1024):
        for start in range(0, COUNT, size):
            assert _is_net(points[start:start + size]), (size, start)


def test_sobol_pairs_of_different_seeds_are_uncorrelated_and_differ(sobol):
    a, b = sobol(7), sobol(8)
    assert not np.allclose(a, b)
    for i in range(2):
        for j in range(2):
            assert abs(np.corrcoef(a[:, i], b[:, j])[0, 1]) < 0.15
    # uniform and not random: the mean of 1024 points is far closer to 1/2 than chance allows
    assert np.abs(a.mean(0) - 0.5).max() < 2e-3


def test_the_simulators_bit_reversal_gives_the_same_pairs(device, probe_program, sobol, tmp_path):
    # on Oclgrind (GPUGI_SIMULATOR) bits are reversed byte by byte, its
    # interpreter lacking the builtin's intrinsic: the same sequences
    probe_program("rng_probe_simulator.cl", "#define GPUGI_SIMULATOR 1\n" + _KERNEL)
    kernel = cl.Kernel(device.program("rng_probe_simulator.cl"), "Rng_probe")
    for seed in (0, 5, 0xFFFFFFFF):
        out = device.empty(8 * COUNT)
        kernel(device.queue, (COUNT,), None, np.uint32(seed), out)
        np.testing.assert_array_equal(device.read(out, 2 * COUNT, np.float32).reshape(COUNT, 2), sobol(seed))
