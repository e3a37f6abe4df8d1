"""Does Oclgrind's uninitialised-value check report initialised data?

Kernels of a few lines, each writing one float4 that is read back and
checked on the host, run on the Oclgrind simulator with its uninitialised-
value plugin: does the plugin report the store itself ("Uninitialized value
written"), and then, when a probe kernel branches on every byte written,
which bytes does it believe uninitialised? A case whose values are
right and whose bytes the plugin flags is a gap of the tool, not of the
kernel: the reason ``bench/oclgrind.py --uninitialized`` cannot settle the
render's kernels (see the README's Reliability section).

    .venv/bin/python bench/oclgrind_uninitialized_gaps.py [--opt-disable]

Prints one line per case (values right or wrong, the store reported or not,
bytes flagged) and writes bench/results/oclgrind_uninitialized_gaps[_opt_disable].json/.txt.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys

import numpy as np
from report import write_results

_SOURCE = r"""
/* a vector built from scalars read from memory (the optimiser starts it from a
 * poison vector) */
__kernel void Gap_vector_from_scalars(const __global float4 *src, __global float4 *dst, const int at) {
    if (get_global_id(0) != 0) return;
    float x = ((const __global float *)src)[get_global_id(0)];
    dst[at] = (float4)(x, 2.0f * x, x + 1.0f, 1.0f);
}
/* a float4 copied */
__kernel void Gap_copy(const __global float4 *src, __global float4 *dst, const int at) {
    if (get_global_id(0) != 0) return;
    dst[at] = src[0];
}
/* a branch on every byte: the plugin reports the bytes it takes as uninitialised */
__kernel void Gap_probe(const __global uchar *bytes, __global int *sink) {
    int i = get_global_id(0);
    if (bytes[i] == 7) sink[0] = 1;
}
"""
# (kernel, whether the host wrote the destination's first float4 before the kernel)
CASES = {
    "vector built from scalars, fresh buffer": ("Gap_vector_from_scalars", False),
    "float4 copied, fresh buffer": ("Gap_copy", False),
    "float4 copied, buffer partly written by the host": ("Gap_copy", True),
}
_AT = 2  # the written float4: bytes 32..47 of the destination


def _expected(kernel: str, first: np.ndarray) -> np.ndarray:
    x = first[0]
    return np.array([x, 2 * x, x + 1, 1], np.float32) if kernel == "Gap_vector_from_scalars" else first


def run_case(case: str, options: list[str]) -> None:
    """In a process with the plugin on: one case, its values and the probe."""
    import pyopencl as cl

    kernel, host_wrote = CASES[case]
    platform = next(p for p in cl.get_platforms() if "oclgrind" in p.name.lower())
    context = cl.Context(platform.get_devices())
    queue = cl.CommandQueue(context)
    program = cl.Program(context, _SOURCE).build(options)
    first = np.array([0.5, 1.5, 2.5, 3.5], np.float32)
    src, dst = (cl.Buffer(context, cl.mem_flags.READ_WRITE, 16 * 4) for _ in range(2))
    cl.enqueue_copy(queue, src, first)
    if host_wrote:
        cl.enqueue_copy(queue, dst, first)  # bytes 0..15 by the host, the rest never
    cl.Kernel(program, kernel)(queue, (1,), None, src, dst, np.int32(_AT))
    queue.finish()
    got = np.empty(16, np.float32)
    cl.enqueue_copy(queue, got, dst)
    right = bool(np.array_equal(got[4 * _AT:4 * _AT + 4], _expected(kernel, first)))
    print(f"values {'right' if right else 'wrong'}", flush=True)
    sink = cl.Buffer(context, cl.mem_flags.READ_WRITE, 16)
    cl.Kernel(program, "Gap_probe")(queue, (16 * (_AT + 1),), None, dst, sink)
    queue.finish()


def flagged_bytes(stderr: str) -> list[int]:
    """Bytes whose branch the plugin reported (the probe's global ids)."""
    found = set()
    for block in re.split(r"\n\s*\n", stderr):
        if "Gap_probe" in block:
            found.update(int(g) for g in re.findall(r"Global\((\d+),", block))
    return sorted(found)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--opt-disable", action="store_true", help="build with -cl-opt-disable")
    parser.add_argument("--case", help=argparse.SUPPRESS)
    args = parser.parse_args()
    options = ["-cl-opt-disable"] if args.opt_disable else []
    if args.case:
        run_case(args.case, options)
        return
    env = dict(os.environ, OCLGRIND_UNINITIALIZED="1")
    results, lines = {}, []
    for case in CASES:
        command = [sys.executable, __file__, "--case", case] + (["--opt-disable"] if args.opt_disable else [])
        done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
        written = range(16 * _AT, 16 * _AT + 16)
        flagged = [b for b in flagged_bytes(done.stderr) if b in written]
        values = "values right" if "values right" in done.stdout else f"no result (exit {done.returncode})"
        store = "reported" if "Uninitialized value written" in done.stderr else "not reported"
        results[case] = {"values_right": "values right" in done.stdout, "store_reported": store == "reported",
                         "bytes_flagged": len(flagged)}
        lines.append(f"{case}: {values}; the store {store}; the probe flags {len(flagged)} of its 16 bytes")
        print(lines[-1], flush=True)
    write_results("oclgrind_uninitialized_gaps" + ("_opt_disable" if args.opt_disable else ""), results, lines)


if __name__ == "__main__":
    main()
