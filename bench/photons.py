"""Photon tracing rate, point kd-tree build time and kNN throughput, the
kNN side by side with ``scipy.spatial.cKDTree`` (``workers=2``).

The photons come from tracing a Cornell-like box (coloured diffuse walls,
a glass sphere, an area light under the ceiling). Each size takes that
many of the stored global photons; the queries are other photons' positions
jittered by a small fraction of the box, so both searches see surface
points, as the final gather does. Both trees index the same points and
answer the same queries in the same run; every time is the median of
``--repeats`` runs after a warm-up (the machine is shared). Besides wall time, the CPU time of the
process (all threads) per query is shown: on a shared machine it is the
steadier measure of the work each search does.

    python bench/photons.py [--sizes 100000,300000,1000000,3000000] [--ks 20,50,100]
                            [--queries N] [--repeats N] [--quick]

Prints the machine and a table, writes ``bench/results/photons.json`` and
the plot ``bench/figures/photons.png``.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from gpu_core.device import get_device  # noqa: E402
from machine import describe  # noqa: E402
from gpu_core.accel.point_tree import PointTree  # noqa: E402
from gpu_core.photons import trace_photon_maps  # noqa: E402
from gpu_core.scene import LIGHT_AREA, CAMERA_PERSP, Camera, Lights, Materials, Scene  # noqa: E402

DEFAULT_SIZES = [100_000, 300_000, 1_000_000, 3_000_000]
DEFAULT_KS = [20, 50, 100]
RESULTS = ROOT / "bench" / "results" / "photons.json"
FIGURE = ROOT / "bench" / "figures" / "photons.png"


# ---- scene ------------------------------------------------------------------------------


def _quad(center, size, axis, sign) -> np.ndarray:
    """Two triangles of a square facing sign * axis."""
    a, b = [k for k in range(3) if k != axis]
    corners = []
    for da, db in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        p = np.array(center, np.float64)
        p[a] += da * size / 2
        p[b] += db * size / 2
        corners.append(p)
    tris = np.array([[corners[0], corners[1], corners[2]], [corners[0], corners[2], corners[3]]])
    if np.cross(tris[0, 1] - tris[0, 0], tris[0, 2] - tris[0, 0])[axis] * sign < 0:
        tris = tris[:, ::-1]
    return tris


def _sphere(center, radius, rings=24, segments=48) -> np.ndarray:
    """UV-sphere triangles wound outwards."""
    t = np.linspace(0, np.pi, rings + 1)[:, None]
    p = np.linspace(0, 2 * np.pi, segments + 1)[None, :]
    pts = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t) * np.ones_like(p)], -1) * radius + center
    a, b, c, d = pts[:-1, :-1], pts[1:, :-1], pts[1:, 1:], pts[:-1, 1:]
    # the first ring's (a, b, d) and the last ring's (b, c, d) would be degenerate at the poles
    return np.concatenate([np.stack([a, b, d], -2)[1:], np.stack([b, c, d], -2)[:-1]]).reshape(-1, 3, 3)


def cornell_box() -> Scene:
    """A 2 m box open nowhere: red and green side walls, white elsewhere,
    a glass sphere, a 0.5 m area light of 100 W under the ceiling."""
    walls = [((0, 0, -1), 2, +1, 0), ((0, 0, 1), 2, -1, 0), ((0, 1, 0), 1, -1, 0), ((0, -1, 0), 1, +1, 0),
             ((-1, 0, 0), 0, +1, 1), ((1, 0, 0), 0, -1, 2)]
    tris = [_quad(c, 2.0, axis, sign) for c, axis, sign, _ in walls] + [_sphere((0.3, 0.2, -0.6), 0.4)]
    mat_of = [m for *_, m in walls for _ in range(2)] + [3] * len(tris[-1])
    materials = Materials.make([
        dict(base_color=(0.73, 0.73, 0.73)), dict(base_color=(0.63, 0.06, 0.05)),
        dict(base_color=(0.14, 0.45, 0.09)), dict(base_color=(1, 1, 1), transmission=1.0, ior=1.5, roughness=0.0),
    ])
    lights = Lights.make([dict(kind=LIGHT_AREA, position=(0, 0, 0.99), power=(100, 100, 100),
                               axis_u=(0.5, 0, 0), axis_v=(0, 0.5, 0))])
    tris = np.concatenate(tris)
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    camera = Camera(matrix=np.eye(4), window=(-1, 1, -1, 1), width=64, height=64, kind=CAMERA_PERSP)
    return Scene(triangles=tris, normals=np.repeat(n[:, None], 3, 1).astype(np.float32),
                 uvs=np.zeros((len(tris), 3, 2), np.float32), material_ids=np.array(mat_of, np.int32),
                 materials=materials, lights=lights, camera=camera)


# ---- timing -----------------------------------------------------------------------------


def _cpu_s() -> float:
    """CPU seconds of this process, all threads (PoCL's and cKDTree's workers)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def median_ms(run, repeats: int) -> tuple[float, float, object]:
    """Median wall time and median CPU time (ms) of ``run()`` over
    ``repeats`` calls after one warm-up, and its last result."""
    result = run()
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), _cpu_s()
        result = run()
        wall.append((time.perf_counter() - start) * 1e3)
        cpu.append((_cpu_s() - start_cpu) * 1e3)
    return statistics.median(wall), statistics.median(cpu), result


def trace(device, stored: int, repeats: int) -> tuple[dict, np.ndarray]:
    """Tracing figures of the Cornell box with enough photons emitted to
    store about ``stored`` global ones, and their positions."""
    scene = cornell_box()
    pilot = trace_photon_maps(device, scene, global_photons=20_000, caustic_photons=5_000)  # also compiles
    per_photon = pilot.stats["stored"]["global"] / pilot.stats["emitted"]["global"]
    emitted = int(stored / per_photon * 1.05) + 1
    runs = [trace_photon_maps(device, scene, global_photons=emitted, caustic_photons=emitted // 4, seed=seed)
            for seed in range(max(repeats, 1))]
    runs.sort(key=lambda maps: maps.stats["ms"]["trace_global"])
    median = runs[len(runs) // 2]  # the run of median tracing time
    s = median.stats
    row = {
        "emitted_global": s["emitted"]["global"],
        "emitted_caustic": s["emitted"]["caustic"],
        "stored_global": s["stored"]["global"],
        "stored_caustic": s["stored"]["caustic"],
        "mean_path_length": s["mean_path_length"]["global"],
        "ms": {k: round(v, 2) for k, v in s["ms"].items()},
        "global_photons_per_s": s["emitted"]["global"] / s["ms"]["trace_global"] * 1e3,
        "caustic_photons_per_s": s["emitted"]["caustic"] / s["ms"]["trace_caustic"] * 1e3,
    }
    return row, median.global_map.positions()


def measure(device, points: np.ndarray, n: int, ks: list[int], queries: int, repeats: int) -> dict:
    """Build and kNN figures of ours and cKDTree on ``n`` of ``points``."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(n)
    pts = points[rng.choice(len(points), n, replace=False)]
    q = points[rng.integers(0, len(points), queries)] + rng.normal(0, 0.005, (queries, 3)).astype(np.float32)
    row = {"photons": n, "queries": queries}
    row["build_ms"], _, tree = median_ms(lambda: PointTree.build(device, pts), repeats)
    row["tree"] = {k: v for k, v in tree.stats.items() if k != "ms"}
    row["scipy_build_ms"], _, ck = median_ms(lambda: cKDTree(pts), repeats)
    row["knn"] = {}
    for k in ks:
        tree = PointTree.build(device, pts, k_hint=k)
        ours_ms, ours_cpu, (_, d2) = median_ms(lambda: tree.knn(q, k), repeats)
        theirs_ms, theirs_cpu, (dist, _) = median_ms(lambda: ck.query(q, k, workers=2), repeats)
        row["knn"][k] = {
            "ours_qps": queries / ours_ms * 1e3,
            "scipy_qps": queries / theirs_ms * 1e3,
            "ours_cpu_us": ours_cpu * 1e3 / queries,
            "scipy_cpu_us": theirs_cpu * 1e3 / queries,
            "same_distances": float(np.isclose(np.sqrt(d2), dist, rtol=1e-4, atol=1e-6).mean()),
        }
    return row


# ---- report -----------------------------------------------------------------------------


def table(trace_row: dict, rows: list[dict]) -> str:
    t = trace_row
    lines = [
        f"tracing (Cornell box, glass sphere): {t['global_photons_per_s'] / 1e3:.0f}k global photons/s "
        f"({t['emitted_global']} emitted, {t['stored_global']} stored, mean path {t['mean_path_length']:.2f} hits), "
        f"{t['caustic_photons_per_s'] / 1e3:.0f}k caustic photons/s ({t['stored_caustic']} stored)",
        "",
        "| photons | build ms | cKDTree build ms | k | ours q/s | cKDTree q/s | ratio "
        "| ours CPU us/q | cKDTree CPU us/q | CPU ratio | same distances |",
        "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        for k, v in r["knn"].items():
            lines.append(
                f"| {r['photons']:,} | {r['build_ms']:.0f} | {r['scipy_build_ms']:.0f} | {k} | {v['ours_qps']:,.0f} "
                f"| {v['scipy_qps']:,.0f} | {v['ours_qps'] / v['scipy_qps']:.2f}x | {v['ours_cpu_us']:.2f} "
                f"| {v['scipy_cpu_us']:.2f} | {v['scipy_cpu_us'] / v['ours_cpu_us']:.2f}x | {v['same_distances']:.4f} |"
            )
    return "\n".join(lines)


def plot(rows: list[dict], ks: list[int], title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["photons"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for i, k in enumerate(ks):
        color = f"C{i}"
        ax1.plot(n, [r["knn"][k]["ours_qps"] for r in rows], "o-", color=color, label=f"ours k={k}")
        ax1.plot(n, [r["knn"][k]["scipy_qps"] for r in rows], "s--", color=color, label=f"cKDTree k={k}")
    ax1.set(xscale="log", yscale="log", xlabel="photons", ylabel="kNN queries / s", title="kNN throughput")
    ax1.legend(fontsize=7)
    ax2.plot(n, [r["build_ms"] for r in rows], "o-", label="ours (device build)")
    ax2.plot(n, [r["scipy_build_ms"] for r in rows], "s--", label="cKDTree")
    ax2.set(xscale="log", yscale="log", xlabel="photons", ylabel="ms", title="tree build")
    ax2.legend(fontsize=7)
    fig.suptitle(title, fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default=",".join(map(str, DEFAULT_SIZES)))
    parser.add_argument("--ks", default=",".join(map(str, DEFAULT_KS)))
    parser.add_argument("--queries", type=int, default=50_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--device", default="cpu", help="OpenCL device spec (default cpu)")
    parser.add_argument("--quick", action="store_true", help="small sizes, one repeat (a smoke run)")
    args = parser.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",")]
    ks = [int(k) for k in args.ks.split(",")]
    if args.quick:
        sizes, ks, args.queries, args.repeats = [20_000, 50_000], [20, 50], 5_000, 1

    device = get_device(args.device)
    about = describe(device)  # the load average when the run starts
    print(about)
    trace_row, points = trace(device, max(sizes), args.repeats)
    rows = [measure(device, points, n, ks, args.queries, args.repeats) for n in sizes if n <= len(points)]
    print(table(trace_row, rows))
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({"machine": about, "queries": args.queries, "repeats": args.repeats,
                                   "trace": trace_row, "rows": rows}, indent=1))
    plot(rows, ks, about, FIGURE)
    print(f"wrote {RESULTS.relative_to(ROOT)} and {FIGURE.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
