"""The inlined math builtins (device/pocl_builtins.h, put before every
program on PoCL; any, select and the integer ones among them) give the builtins' results: the same kernel built with
them and built plainly by the driver agree, at NaN operands, signed zeros,
infinities, and at vectors so tiny or huge their squares under- or overflow."""

import numpy as np
import pyopencl as cl
import pytest

from gpu_core.device.programs import build_options


_KERNEL = """
/* every row of `a`, `b` (float4) through the builtins the header replaces;
 * out holds OUTPUTS float4 per row */
__kernel void Builtins_probe(const __global float4 *a, const __global float4 *b, __global float4 *out) {
    int i = get_global_id(0);
    float4 x = a[i], y = b[i];
    float3 u = x.xyz, v = y.xyz;
    __global float4 *o = out + OUTPUTS * i;
    o[0] = (float4)(fmin(x.x, y.x), fmax(x.x, y.x), fabs(x.x), sqrt(x.x));
    o[1] = (float4)(fmin(u, v), dot(u, v));
    o[2] = (float4)(fmax(u, v), dot(x, y));
    o[3] = (float4)(fmin(u, y.w), length(u));
    o[4] = (float4)(fmax(u, y.w), clamp(x.x, y.y, y.z));
    o[5] = (float4)(fabs(u), mix(x.x, y.x, y.w));
    o[6] = (float4)(cross(u, v), length(x.xy));
    o[7] = (float4)(normalize(u), (float)clamp((int)x.w, -2, 3));
    o[8] = (float4)(clamp(u, y.y, y.z), mix(x.y, y.y, 0.25f));
    o[9] = (float4)(mix(u, v, y.w), (float)(isnan(x.x) + 2 * isinf(x.x) + 4 * isfinite(x.x)));
    o[10] = fmin(x, y) + fmax(x, 1.0f) * 0.0f;
    ulong bits = ((ulong)as_uint(x.x) << 32) | as_uint(y.y);
    o[11] = (float4)((float)popcount(as_uint(x.x)), (float)popcount(bits), 0.0f, 0.0f);
    int4 m = as_int4(x);  /* sign bits set and not, and lanes nonzero without one */
    o[12] = select(x, y, m);
    o[13] = (float4)((float)any(m), (float)any(m & (int4)(0x7fffffff)), (float)any(as_int(x.x)),
                     select(x.y, y.y, as_int(x.z)));
    int i0 = as_int(x.x), i1 = as_int(y.y);  /* integers of every sign and size, 0 and INT_MIN among them */
    uint u0 = as_uint(x.y), u1 = as_uint(y.x);
    int3 i3 = as_int3(x.xyz), j3 = as_int3(y.xyz);
    o[14] = as_float4((int4)(min(i0, i1), max(i0, i1), (int)abs(i0), clz(i0)));
    o[15] = as_float4((uint4)(min(u0, u1), max(u0, u1), clz(u0), abs(i1)));
    o[16] = as_float4((int4)(min(i3, j3), 0));
    o[17] = as_float4((int4)(max(i3, j3), 0));
    o[18] = as_float4(max(as_int4(x), as_int4(y)));
    o[19] = as_float4(isless(x, y));
    o[20] = (float4)(floor(x.x), floor(x.yz), 0.0f);
    o[21] = (float4)(floor(u), 0.0f);
}
"""
OUTPUTS = 22
# outputs computed exactly alike (selections, exact operations); the rest may round differently
_EXACT = [(0, slice(0, 4)), (1, slice(0, 3)), (2, slice(0, 3)), (3, slice(0, 3)), (4, slice(0, 4)), (5, slice(0, 3)),
          (7, slice(3, 4)), (8, slice(0, 3)), (9, slice(3, 4)), (10, slice(0, 4)), (11, slice(0, 2)),
          (12, slice(0, 4)), (13, slice(0, 4)), (20, slice(0, 4)), (21, slice(0, 4))]
# integer outputs, compared bit for bit
_BITS = range(14, 20)


def _rows():
    """Operands: ordinary values and the edge cases of each builtin."""
    nan, inf = np.float32(np.nan), np.float32(np.inf)
    special = [
        [nan, 1.0, -2.0, 0.0], [1.0, nan, 3.0, 0.0],  # a NaN operand loses in fmin and fmax
        [-0.0, 0.0, -inf, 5.0], [inf, -inf, 0.0, -7.0],
        [1e-25, 0.0, 0.0, 0.0], [3e20, 4e20, 0.0, 1.0],  # squares that underflow, overflow
        [1e-20, 2e-20, -2e-20, 0.0], [0.0, 0.0, 0.0, 0.0], [-4.0, 2.0, 1e-30, 3.0],
    ]
    rng = np.random.default_rng(3)
    ordinary = rng.normal(size=(64, 4)) * rng.choice([1e-3, 1.0, 1e3], size=(64, 1))
    a = np.vstack([special, ordinary]).astype(np.float32)
    b = np.vstack([np.roll(special, 3, axis=0), rng.normal(size=(64, 4))]).astype(np.float32)
    b[:, 1], b[:, 2] = np.minimum(b[:, 1], b[:, 2]), np.maximum(b[:, 1], b[:, 2])  # clamp's bounds in order
    b[:len(special), 3] = np.nan_to_num(b[:len(special), 3], nan=0.5)
    return a, b


def _run(device, program, a, b):
    out = np.zeros((len(a), OUTPUTS, 4), np.float32)
    a_buf, b_buf, out_buf = device.to_device(a), device.to_device(b), device.empty(out.nbytes)
    program.Builtins_probe(device.queue, (len(a),), None, a_buf, b_buf, out_buf)
    cl.enqueue_copy(device.queue, out, out_buf)
    return out


def test_inlined_builtins_give_the_builtins_results(device, probe_program):
    probe_program("builtins_probe.cl", _KERNEL)
    a, b = _rows()
    ours = _run(device, device.program("builtins_probe.cl", {"OUTPUTS": OUTPUTS}), a, b)
    # the driver's own builtins, built with the options the program memo uses
    options = device.programs._cache_entry("builtins_probe.cl", build_options({"OUTPUTS": OUTPUTS}))[1]
    plain = cl.Program(device.context, _KERNEL).build(options=list(options))
    reference = _run(device, plain, a, b)
    for row, cols in _EXACT:
        np.testing.assert_array_equal(ours[:, row, cols], reference[:, row, cols], err_msg=f"output {row}")
    for row in _BITS:
        np.testing.assert_array_equal(ours[:, row].view(np.int32), reference[:, row].view(np.int32),
                                      err_msg=f"output {row}")
    # the rest to rounding: of the result, or of the operands' products where terms cancel (dot, cross, mix)
    terms = (np.abs(a) * np.abs(b)).sum(axis=1) + np.abs(a).sum(axis=1) + np.abs(b).sum(axis=1)
    tolerance = 2e-6 * np.abs(reference) + 4 * np.finfo(np.float32).eps * terms[:, None, None]
    both_nan = np.isnan(ours) & np.isnan(reference)
    with np.errstate(invalid="ignore"):  # infinities of the same sign differ by NaN
        close = both_nan | (np.abs(ours - reference) <= tolerance) | (ours == reference)
    assert close.all(), np.argwhere(~close)
    # the tiny and huge vectors keep their length and direction
    assert np.all(np.isfinite(ours[4:6, 3, 3])) and np.all(ours[4:6, 3, 3] > 0)
    np.testing.assert_allclose(np.linalg.norm(ours[4:7, 7, :3], axis=1), 1.0, rtol=1e-6)


def test_the_header_goes_before_programs_on_pocl_only(device, probe_program):
    probe_program("builtins_probe.cl", _KERNEL)
    source = device.programs._cache_entry("builtins_probe.cl", ())[0]
    on_pocl = "portable computing language" in device.context.devices[0].platform.name.lower()
    assert ("#define dot Inline_dot" in source) == on_pocl


_TRIG_KERNEL = """
/* asin, native_sin and native_cos of every x */
__kernel void Trig_probe(const __global float *x, __global float4 *out) {
    int i = get_global_id(0);
    out[i] = (float4)(asin(x[i]), native_sin(x[i]), native_cos(x[i]), 0.0f);
}
"""


def _trig(device, probe_program, x):
    probe_program("trig_probe.cl", _TRIG_KERNEL)
    program = device.program("trig_probe.cl", {})
    x = np.asarray(x, np.float32)
    out = np.zeros((len(x), 4), np.float32)
    x_buf, out_buf = device.to_device(x), device.empty(out.nbytes)
    cl.Kernel(program, "Trig_probe")(device.queue, (len(x),), None, x_buf, out_buf)
    cl.enqueue_copy(device.queue, out, out_buf)
    return x, out


def _ulps(ours, exact):
    """Distance of float32 results from the float64 values in units of the last place there."""
    spacing = np.spacing(np.abs(exact).astype(np.float32)).astype(np.float64)
    return np.abs(ours.astype(np.float64) - exact) / spacing


def test_asin_within_four_ulp_and_nan_outside_its_domain(device, probe_program):
    rng = np.random.default_rng(5)
    inside = np.concatenate([np.linspace(-1, 1, 20001), [0.5, -0.5, np.nextafter(np.float32(0.5), 1), 1e-30, -1e-8],
                             rng.uniform(-1, 1, 5000), 10.0 ** rng.uniform(-38, 0, 2000)])
    x, out = _trig(device, probe_program, np.concatenate([inside, [1.5, -2.0, np.nan]]))
    n = len(inside)
    exact = np.arcsin(x[:n].astype(np.float64))
    assert _ulps(out[:n, 0], exact).max() <= 4.0  # OpenCL's bound for asin
    assert np.all(np.signbit(out[:n, 0]) == np.signbit(x[:n]))
    assert np.isnan(out[n:, 0]).all()


def test_native_sin_and_cos_close_to_the_exact_values_everywhere(device, probe_program):
    if "portable computing language" not in device.context.devices[0].platform.name.lower():
        pytest.skip("the inlined native_sin and native_cos are PoCL's; elsewhere their accuracy is the driver's")
    rng = np.random.default_rng(6)
    reach = np.concatenate([np.linspace(-7, 7, 20001), rng.uniform(-8191, 8191, 20000), [0.0, 2 * np.pi, -np.pi / 2]])
    beyond = np.array([8192.0, -1e6, 3e30, np.inf, np.nan])
    x, out = _trig(device, probe_program, np.concatenate([reach, beyond]))
    n = len(reach)
    x64 = x[:n].astype(np.float64)
    # within a few float32 roundings of the float32 argument's exact sine and cosine
    assert np.abs(out[:n, 1] - np.sin(x64)).max() <= 2e-7
    assert np.abs(out[:n, 2] - np.cos(x64)).max() <= 2e-7
    # beyond the reduction's reach: the device's own function, finite where x is
    assert np.all(np.abs(out[n:n + 3, 1:3]) <= 1.0) and np.isnan(out[n + 3:, 1:3]).all()
