"""The kernels whose work-items share a work-group's memory, run under
Oclgrind's data-race detector: a GPU runs a group's work-items at once,
where PoCL runs them one after another between barriers and so never shows
a missing one. Checked: the point tree's one-launch build shared by a group
of 16, and the kd-tree build's GPU forms (a chunk's bounds and a node's SAH
search shared among lanes). In a process of its own: Oclgrind reads its
options when it starts."""

from __future__ import annotations

import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

_CHECKS = """
import sys
sys.path.insert(0, {root!r})
import numpy as np
import pyopencl as cl
from gpu_core.device import Device, get_device
from gpu_core.accel.point_tree import PointTree
from gpu_core.accel import kdtree

device = get_device("oclgrind")
# a control: the detector sees a group's writes read without a barrier
program = cl.Program(device.context, '''
__kernel void Control_unsynchronised(__global int *v) {{
    int i = get_local_id(0);
    v[i] = i;
    v[(i + 1) % get_local_size(0)] += 1;
}}''').build()
buffer = device.zeros(4 * 16)
program.Control_unsynchronised(device.queue, (16,), (16,), buffer)
device.queue.finish()
print("control ran", flush=True)
rng = np.random.default_rng(1)
points = rng.random((1500, 3)).astype(np.float32)
power, directions = rng.random((1500, 3)).astype(np.float32), rng.normal(size=(1500, 3)).astype(np.float32)
tree = PointTree.build(device, points, power, directions, -directions, k_hint=20, serial_max=1 << 20,
                       serial_group=16)
assert "serial" in tree.stats["ms"] and tree.stats["large_levels"] >= 3
print("point tree built", flush=True)
Device.is_cpu = property(lambda self: False)  # the GPU's forms of the kd-tree build
corners = rng.random((300, 3, 3)).astype(np.float32)
triangles = corners[:, :1] + 0.05 * (corners - corners[:, :1])
tree = kdtree.build(device, triangles)
assert tree.stats["large_levels"] >= 1 and tree.stats["small_levels"] >= 1, tree.stats
print("kd-tree built", flush=True)
"""


def test_work_group_kernels_have_no_data_races_under_oclgrind():
    env = dict(os.environ, OCLGRIND_DATA_RACES="1", PYOPENCL_NO_CACHE="1")
    done = subprocess.run([sys.executable, "-c", _CHECKS.format(root=ROOT)], env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.split("\n")[:3] == ["control ran", "point tree built", "kd-tree built"]
    reports = [block for block in done.stderr.split("\n\n") if "data race" in block]
    assert reports and all("Control_unsynchronised" in block for block in reports), "\n\n".join(
        block for block in reports if "Control_unsynchronised" not in block)[:3000]
