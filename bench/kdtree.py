"""Kd-tree build time and closest-hit throughput, side by side with Embree.

Both trace the same procedural meshes (clusters of displaced spheres) with
the same rays in the same run: incoherent rays (random origins in the
scene's box, random directions), the same rays sorted (by direction octant,
then along a Morton curve of their origins: what ordering alone gives) and
camera rays (a pinhole camera looking at the mesh). Every figure is the median of ``--repeats`` runs after a
warm-up. Embree (through ``embreex``) builds with its own threads;
``embreex`` traces its rays one at a time on one thread, so its
throughput is also measured on two forked processes, one per core, each
tracing half of the rays.

Then the worst cases for a kd-tree build, beside Embree's build of the same
triangles: a soup of 41k random triangles overlapping across a tenth of
the scene each, a fan of 4,096 triangles around one vertex and a stack of
1,000 copies of one triangle.

    python bench/kdtree.py [--sizes 1000,10000] [--rays N] [--repeats N] [--quick]
                           [--device cpu] [--tag TAG]

Prints the machine and the tables, writes ``bench/results/kdtree.json`` and
the plot ``bench/figures/kdtree.png`` (``kdtree_TAG.*`` with ``--tag``, so a
partial run leaves the full one's figures alone; ``kdtree_quick.*`` with
``--quick``).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from gpu_core.accel import kdtree  # noqa: E402
from gpu_core.accel.point_tree import morton_codes  # noqa: E402
from gpu_core.device import get_device  # noqa: E402
from machine import describe  # noqa: E402

DEFAULT_SIZES = [1_000, 10_000, 100_000, 650_000, 1_000_000]
KINDS = ("incoherent", "sorted", "camera")  # ray sets, in the tables' order
RESULTS = ROOT / "bench" / "results" / "kdtree.json"
FIGURE = ROOT / "bench" / "figures" / "kdtree.png"


# ---- scene and rays ---------------------------------------------------------------------


def blob_mesh(triangles: int, seed: int = 0) -> np.ndarray:
    """About ``triangles`` triangles: displaced UV spheres scattered in a box, (N, 3, 3) float32."""
    rng = np.random.default_rng(seed)
    blobs = int(np.clip(triangles // 2000, 1, 32))
    rings = max(3, int(round(np.sqrt(triangles / blobs / 4.0))))
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, 2 * rings + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    unit = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    meshes = []
    for _ in range(blobs):
        # a bumpy sphere: the radius varies with a few random waves
        freq = rng.uniform(2.0, 6.0, (3, 3))
        phase = rng.uniform(0.0, 2.0 * np.pi, 3)
        bumps = sum(np.sin(unit @ freq[k] + phase[k]) for k in range(3))
        radius = rng.uniform(0.3, 1.0) * (1.0 + 0.15 * bumps)
        pts = unit * radius[..., None] + rng.uniform(-2.0, 2.0, 3)
        a, b, c, d = pts[:-1, :-1], pts[:-1, 1:], pts[1:, :-1], pts[1:, 1:]
        # one triangle per quad in the rings at the poles (the other has two corners at the pole)
        lower, upper = np.stack([a, c, d], -2)[:-1], np.stack([a, d, b], -2)[1:]
        meshes.append(np.concatenate([lower.reshape(-1, 3, 3), upper.reshape(-1, 3, 3)]))
    return np.concatenate(meshes).astype(np.float32)


def incoherent_rays(tris: np.ndarray, count: int, seed: int = 1):
    """Origins uniform in the mesh's box, directions uniform on the sphere."""
    rng = np.random.default_rng(seed)
    lo, hi = tris.reshape(-1, 3).min(0), tris.reshape(-1, 3).max(0)
    org = rng.uniform(lo, hi, (count, 3))
    dirs = rng.standard_normal((count, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    return org.astype(np.float32), dirs.astype(np.float32)


def sorted_rays(org: np.ndarray, dirs: np.ndarray):
    """The rays ordered by direction octant, then along a Morton curve of
    their origins (10 bits an axis over their box)."""
    octant = (dirs[:, 0] > 0).astype(np.int64) | ((dirs[:, 1] > 0) << 1) | ((dirs[:, 2] > 0) << 2)
    order = np.lexsort((morton_codes(org), octant))
    return np.ascontiguousarray(org[order]), np.ascontiguousarray(dirs[order])


def camera_rays(tris: np.ndarray, count: int):
    """A pinhole camera (about ``count`` pixels, 50 degrees) in front of the mesh, looking at its centre."""
    lo, hi = tris.reshape(-1, 3).min(0), tris.reshape(-1, 3).max(0)
    centre, extent = 0.5 * (lo + hi), float(np.max(hi - lo))
    eye = centre + extent * np.array([0.25, -1.0, 0.35])
    forward = (centre - eye) / np.linalg.norm(centre - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    side = max(1, int(np.sqrt(count)))
    s = np.tan(np.radians(25.0)) * ((np.arange(side) + 0.5) / side * 2.0 - 1.0)
    x, y = np.meshgrid(s, -s)
    dirs = forward + x.reshape(-1, 1) * right + y.reshape(-1, 1) * up
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    org = np.broadcast_to(eye, dirs.shape)
    return org.astype(np.float32), dirs.astype(np.float32)


# ---- timing -----------------------------------------------------------------------------


def median_ms(run, repeats: int) -> tuple[float, object]:
    """Median wall time of ``run()`` over ``repeats`` calls after one warm-up, and its last result."""
    result = run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times), result


def embree_build(tris):
    """An Embree scene over ``tris``, committed (Embree builds on the first query).

    Returns the scene, its mesh (to be kept alive with it) and the build's milliseconds.
    """
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    scene = rtcs.EmbreeScene()
    mesh = TriangleMesh(scene, tris)
    start = time.perf_counter()
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))
    return scene, mesh, (time.perf_counter() - start) * 1e3


_FORKED_SCENE = None


def _embree_half(args):
    """Closest hits of one slice of rays in a forked process (the scene is inherited)."""
    org, dirs = args
    out = _FORKED_SCENE.run(org, dirs, output=1)
    return out["primID"], out["tfar"]


def embree_trace(scene, org, dirs, pool=None):
    """Embree's closest hits (triangle, t), in this thread or split over ``pool``."""
    if pool is None:
        out = scene.run(org, dirs, output=1)
        return out["primID"], out["tfar"]
    halves = np.array_split(np.arange(len(org)), 2)
    parts = pool.map(_embree_half, [(org[h], dirs[h]) for h in halves])
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def worst_cases() -> dict[str, np.ndarray]:
    """Triangle sets that defeat spatial splits, (N, 3, 3) float32 each."""
    rng = np.random.default_rng(7)
    soup = rng.random((41_000, 1, 3)) + 0.15 * (rng.random((41_000, 3, 3)) - 0.5) * 2.0
    ring = np.linspace(0.0, 2.0 * np.pi, 4_097)
    rim = np.stack([np.cos(ring), np.sin(ring), np.full_like(ring, 0.1)], -1)
    fan = np.stack([np.zeros((4_096, 3)), rim[:-1], rim[1:]], 1)
    tri = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    stack = tri[None] + np.linspace(0.0, 1e-3, 1_000)[:, None, None] * np.array([0.0, 0.0, 1.0])
    return {"soup of 41k overlapping triangles": soup, "fan of 4,096 triangles": fan,
            "stack of 1,000 triangles": stack}


def measure_worst(device, name: str, tris: np.ndarray, repeats: int) -> dict:
    """Our build against Embree's on one worst case."""
    tris = np.ascontiguousarray(tris, np.float32)
    build_ms, tree = median_ms(lambda: kdtree.build(device, tris), repeats)
    commits = [embree_build(tris)[2] for _ in range(repeats + 1)][1:]
    stats = tree.stats
    return {"case": name, "triangles": len(tris), "build_ms": build_ms, "embree_build_ms": statistics.median(commits),
            "leaf_references": stats["leaf_references"], "max_leaf_size": stats["max_leaf_size"],
            "depth": stats["depth"], "large_levels": stats["large_levels"]}


def worst_table(rows) -> str:
    head = ("case", "build ms", "Embree ms", "ratio", "leaf refs / triangle", "largest leaf", "depth")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        lines.append(f"| {r['case']} | {r['build_ms']:.1f} | {r['embree_build_ms']:.1f} | "
                     f"{r['build_ms'] / r['embree_build_ms']:.1f} | {r['leaf_references'] / r['triangles']:.1f} | "
                     f"{r['max_leaf_size']} | {r['depth']} |")
    return "\n".join(lines)


# ---- one size ---------------------------------------------------------------------------


def measure(device, triangles: int, rays: int, repeats: int) -> dict:
    """Build and trace figures of ours and Embree's for one mesh size."""
    global _FORKED_SCENE
    tris = blob_mesh(triangles)
    row = {"triangles": len(tris)}

    build_ms, tree = median_ms(lambda: kdtree.build(device, tris), repeats)
    row["build_ms"] = build_ms
    row["stages_ms"] = {k: round(v, 2) for k, v in tree.stats["ms"].items()}
    row["tree"] = {k: v for k, v in tree.stats.items() if k != "ms"}

    # Embree: geometry copy (TriangleMesh) and its build (commit) timed apart
    commits, totals = [], []
    for _ in range(repeats + 1):
        start = time.perf_counter()
        scene, mesh, commit_ms = embree_build(tris)
        totals.append((time.perf_counter() - start) * 1e3)
        commits.append(commit_ms)
    row["embree_build_ms"] = statistics.median(commits[1:])
    row["embree_build_total_ms"] = statistics.median(totals[1:])

    _FORKED_SCENE = scene
    with multiprocessing.get_context("fork").Pool(2) as pool:
        kinds = {"incoherent": incoherent_rays(tris, rays)}
        kinds["sorted"] = sorted_rays(*kinds["incoherent"])
        kinds["camera"] = camera_rays(tris, rays)
        for kind, (org, dirs) in kinds.items():
            ours_ms, (t, tri) = median_ms(lambda: tree.intersect(org, dirs), repeats)
            one_ms, (e_tri, e_t) = median_ms(lambda: embree_trace(scene, org, dirs), repeats)
            two_ms, _ = median_ms(lambda: embree_trace(scene, org, dirs, pool), repeats)
            n = len(org)
            same_t = np.isclose(np.where(tri >= 0, t, np.inf), np.where(e_tri >= 0, e_t, np.inf), rtol=1e-4)
            row[kind] = {
                "rays": n,
                "hit_fraction": float((tri >= 0).mean()),
                "ours_mrays": n / ours_ms / 1e3,
                "embree_1t_mrays": n / one_ms / 1e3,
                "embree_2p_mrays": n / two_ms / 1e3,
                "same_triangle": float((tri == e_tri).mean()),
                "same_distance": float(same_t.mean()),
            }
    _FORKED_SCENE = None
    return row


# ---- report -----------------------------------------------------------------------------


def table(rows) -> str:
    """The results as a markdown table, ratios ours / Embree."""
    head = ("triangles", "build ms", "Embree ms", "ratio", "incoh. Mray/s", "Embree 1t/2p", "ratio",
            "sorted Mray/s", "Embree 1t/2p", "ratio", "camera Mray/s", "Embree 1t/2p", "ratio",
            "same hit % inc/sorted/cam")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [f"{r['triangles']:,}", f"{r['build_ms']:.1f}", f"{r['embree_build_ms']:.1f}",
                 f"{r['build_ms'] / r['embree_build_ms']:.2f}"]
        for kind in KINDS:
            k = r[kind]
            cells += [f"{k['ours_mrays']:.2f}", f"{k['embree_1t_mrays']:.2f} / {k['embree_2p_mrays']:.2f}",
                      f"{k['ours_mrays'] / max(k['embree_1t_mrays'], k['embree_2p_mrays']):.2f}"]
        cells.append(" / ".join(f"{100 * r[kind]['same_triangle']:.2f}" for kind in KINDS))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(rows, path: Path) -> None:
    """Build time and throughput against triangle count, ours beside Embree."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["triangles"] for r in rows]
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    # colour: what is measured; line: solid ours, dashed Embree
    left.loglog(n, [r["build_ms"] for r in rows], "o-", color="C0", label="ours (PoCL)")
    left.loglog(n, [r["embree_build_ms"] for r in rows], "s--", color="C0", label="Embree (commit)")
    left.loglog(n, [r["embree_build_total_ms"] for r in rows], "s:", color="C7", label="Embree (copy + commit)")
    left.set(xlabel="triangles", ylabel="build time (ms)", title="Build")
    for kind, marker, colour in (("incoherent", "o", "C1"), ("sorted", "s", "C3"), ("camera", "^", "C2")):
        right.semilogx(n, [r[kind]["ours_mrays"] for r in rows], marker + "-", color=colour, label=f"ours, {kind}")
        best = [max(r[kind]["embree_1t_mrays"], r[kind]["embree_2p_mrays"]) for r in rows]
        right.semilogx(n, best, marker + "--", color=colour, label=f"Embree, {kind}")
    right.set(xlabel="triangles", ylabel="closest hits (Mrays/s)", title="Closest-hit throughput")
    for ax in (left, right):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default=",".join(map(str, DEFAULT_SIZES)),
                        help="triangle counts, comma-separated")
    parser.add_argument("--rays", type=int, default=1 << 18, help="rays per kind (default 262144)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs after the warm-up (median)")
    parser.add_argument("--quick", action="store_true", help="small sizes, few rays, one timed run")
    parser.add_argument("--device", default="cpu", help="OpenCL device spec (default cpu)")
    parser.add_argument("--tag", default="", help="suffix of the output files (default: none, or quick)")
    args = parser.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",")]
    if args.quick:
        sizes, args.rays, args.repeats = [s for s in sizes if s <= 10_000] or sizes[:1], 1 << 14, 1

    device = get_device(args.device)
    print(describe(device))
    print(f"rays per kind: {args.rays:,}; median of {args.repeats} run(s) after a warm-up")
    rows = []
    for size in sizes:
        rows.append(measure(device, size, args.rays, args.repeats))
        r = rows[-1]
        print(f"  {r['triangles']:,} triangles: build {r['build_ms']:.0f} ms {r['stages_ms']}", flush=True)
    print(table(rows))
    print("ratio: ours / Embree (build: lower is better; throughput, against Embree's faster of 1 thread"
          " and 2 processes: higher is better)")
    worst = [measure_worst(device, name, tris, args.repeats) for name, tris in worst_cases().items()]
    print(worst_table(worst))
    suffix = f"_{args.tag}" if args.tag else "_quick" if args.quick else ""
    results, figure = (path.with_name(path.stem + suffix + path.suffix) for path in (RESULTS, FIGURE))
    results.parent.mkdir(parents=True, exist_ok=True)
    results.write_text(json.dumps({"machine": describe(device), "rays": args.rays, "repeats": args.repeats,
                                   "rows": rows, "worst_cases": worst}, indent=1))
    plot(rows, figure)
    print(f"wrote {results.relative_to(ROOT)} and {figure.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
