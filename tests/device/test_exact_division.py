"""Division and square root are correctly rounded on every device that
offers it (programs.py asks for it), so kernels compute alike on PoCL and
on a GPU driver, whose default division is allowed 2.5 ulp."""

import numpy as np
import pyopencl as cl
import pytest


_KERNEL = """
__kernel void Division_probe(const __global float *a, const __global float *b, __global float4 *out) {
    int i = get_global_id(0);
    out[i] = (float4)(a[i] / b[i], 1.0f / b[i], sqrt(a[i]), b[i] / b[i]);
}
"""


def _offers_exact_division(device) -> bool:
    return bool(device.device.single_fp_config & cl.device_fp_config.CORRECTLY_ROUNDED_DIVIDE_SQRT)


def test_programs_ask_for_exact_division_where_the_device_offers_it(device, probe_program):
    probe_program("division_probe.cl", _KERNEL)
    options = device.programs._cache_entry("division_probe.cl", ())[1]
    assert ("-cl-fp32-correctly-rounded-divide-sqrt" in options) == _offers_exact_division(device)


def test_division_and_square_root_round_as_numpy_does(device, probe_program):
    probe_program("division_probe.cl", _KERNEL)
    if not _offers_exact_division(device):
        pytest.skip("the device does not offer correctly rounded division")
    rng = np.random.default_rng(5)
    count = 1 << 14
    a = (rng.random(count) * 10.0 ** rng.integers(-30, 30, count)).astype(np.float32)
    b = (rng.random(count) * 10.0 ** rng.integers(-30, 30, count) + 1e-30).astype(np.float32)
    out = np.zeros((count, 4), np.float32)
    a_buf, b_buf, out_buf = device.to_device(a), device.to_device(b), device.empty(out.nbytes)
    program = device.program("division_probe.cl")
    program.Division_probe(device.queue, (count,), None, a_buf, b_buf, out_buf)
    cl.enqueue_copy(device.queue, out, out_buf)
    np.testing.assert_array_equal(out[:, 0], a / b)
    np.testing.assert_array_equal(out[:, 1], np.float32(1.0) / b)
    np.testing.assert_array_equal(out[:, 2], np.sqrt(a))
    assert (out[:, 3] == 1.0).all()
