"""Time against error: GPU GI's presets and knobs beside Cycles.

For each scene, a high-sample Cycles render with a 1-pixel box filter is
the reference, rendered here once and kept in bench/results/ (the tests'
stored references have Blender's default film instead). Then, in the same run: Cycles at 4..1024
samples with and without its denoiser (set up like the reference: box
filter, no clamp, no glossy filter, deep bounces), Cycles with adaptive
sampling at 16 and 64 (its default threshold 0.01, a quarter of the
samples first, as GPU GI's presets take them), GPU GI's presets as
rendered and denoised (Open Image Denoise from the albedo and normal
passes, as Cycles' denoiser), and a sweep of its main knobs from the
Preview preset, all with the reference's 1-pixel box filter. Each
configuration's render time (median of --repeats, the bpy render call
including export) and its errors against the reference
go into a table and a log-log plot, bench/figures/tradeoff[_SIZE].png:

* display relative RMSE: of display values (a Reinhard curve, then sRGB;
  the metric of tests/gi/test_gi_vs_cycles.py), the plotted error;
* HDR-FLIP: NVIDIA's perceptual error of HDR images (flip-evaluator), the
  mean over the image, as rendering papers report it;
* the relative RMSE of linear light, printed beside them.

Each preset's line says whether it is on the Pareto front of time against
display error (no other configuration both faster and closer), and the
target line whether GI reaches Cycles' 64-sample error faster.

With ``--mnee`` Cycles (its reference and every Cycles row) is set up as
for refractive caustics: manifold next-event estimation, each smooth-shaded
mesh of refractive materials a caustic caster, every other mesh a receiver,
every light a caustic light. A path tracer alone finds light that reaches
a diffuse surface through glass from a small light only when a path hits
the light by chance (the caustics scene); MNEE finds those paths directly.

    python bench/tradeoff.py [--scenes cornell_box box_torus caustics]
        [--size 64] [--reference-samples 4096] [--repeats 3] [--mnee] [--quick] [--tag NAME]
"""

from __future__ import annotations

import argparse
import os
import statistics

import sys

import numpy as np

from bpy_render import ROOT, load_bpy, open_scene, render
from machine import describe
from report import RESULTS, write_results

sys.path.insert(0, os.path.join(ROOT, "tests"))
sys.path.insert(0, os.path.join(ROOT, "tests", "gi"))
sys.path.insert(0, os.path.join(ROOT, "tests", "references"))
from make_references import configure as cycles_reference_settings  # noqa: E402
from test_gi_vs_cycles import display  # noqa: E402

FIGURE = os.path.join(ROOT, "bench", "figures", "tradeoff.png")
CYCLES_SAMPLES = (4, 16, 64, 256, 1024)
CYCLES_ADAPTIVE = (16, 64)  # samples of the Cycles rows with adaptive sampling
CYCLES_THRESHOLD = 0.01  # Cycles' default noise threshold
PRESETS = ("DRAFT", "PREVIEW", "FINAL")
SWEEPS = {  # knob -> values, each applied on top of the Preview preset
    "samples": (4, 16, 64),
    "global_photons": (25_000, 100_000, 400_000),
    "cache_seeds": (250, 1000, 4000),
    "gather_rays": (64, 256, 1024),
    "photon_k": (20, 50, 100),
    "caustic_k": (8, 32, 64),
    "gi_subpixels": (1, 2),
    "noise_threshold": (0.0, 0.005, 0.02),
}


def relative_rmse(image: np.ndarray, reference: np.ndarray) -> float:
    return float(np.sqrt(((image - reference) ** 2).mean()) / max(reference.mean(), 1e-30))


def hdr_flip(image: np.ndarray, reference: np.ndarray) -> float:
    """Mean HDR-FLIP error (linear RGB, exposures chosen by FLIP)."""
    import flip_evaluator

    def linear(a):
        return np.ascontiguousarray(np.clip(np.nan_to_num(a, nan=0.0, posinf=0.0), 0.0, None), np.float32)

    return float(flip_evaluator.evaluate(linear(reference), linear(image), "HDR", applyMagma=False)[1])


def errors(image: np.ndarray, reference: np.ndarray) -> dict:
    """Relative RMSE of display values (the plotted error), HDR-FLIP and relative RMSE of linear light."""
    return dict(error=relative_rmse(display(image), display(reference)), flip=hdr_flip(image, reference),
                linear=relative_rmse(image, reference))


def cycles_settings(scene, samples: int, denoise: bool, adaptive: bool = False, mnee: bool = False) -> None:
    cycles_reference_settings(scene, scene.render.resolution_x, samples, box_filter=True)
    scene.cycles.use_denoising = denoise
    if adaptive:
        scene.cycles.use_adaptive_sampling = True
        scene.cycles.adaptive_threshold, scene.cycles.adaptive_min_samples = CYCLES_THRESHOLD, samples // 4
    if mnee:
        caustic_casters(scene)


def _refractive(material) -> bool:
    """Whether a material's node tree has a glass, refraction or transmitting Principled BSDF."""
    nodes = material.node_tree.nodes if material is not None and material.node_tree else []
    return any(n.type in ("BSDF_GLASS", "BSDF_REFRACTION") or
               (n.type == "BSDF_PRINCIPLED" and n.inputs["Transmission Weight"].default_value > 0.0) for n in nodes)


def caustic_casters(scene) -> None:
    """Cycles' manifold next-event estimation on: smooth refractive meshes
    cast caustics, the other meshes receive them, every light casts them."""
    for obj in scene.objects:
        if obj.type == "MESH":
            mesh = obj.data
            caster = (any(_refractive(m) for m in mesh.materials) and len(mesh.polygons) > 0
                      and all(p.use_smooth for p in mesh.polygons))
            obj.cycles.is_caustics_caster, obj.cycles.is_caustics_receiver = caster, not caster
        elif obj.type == "LIGHT":
            obj.data.cycles.is_caustics_light = True


def reference(bpy, name: str, size: int, samples: int, mnee: bool = False) -> np.ndarray:
    """The scene rendered by Cycles at ``samples`` samples with a 1-pixel box
    filter, cached (the tests' stored references have Blender's default film)."""
    path = os.path.join(RESULTS, f"reference_{name}_{size}_{samples}{'_mnee' if mnee else ''}.npy")
    if os.path.exists(path):
        return np.load(path)
    scene = open_scene(bpy, name, size)
    cycles_settings(scene, samples, False, mnee=mnee)
    image, seconds = render(bpy, scene, "CYCLES")
    print(f"  reference: Cycles {samples} samples in {seconds:.1f} s")
    os.makedirs(RESULTS, exist_ok=True)
    np.save(path, image)
    return image


def timed(bpy, name, size, engine, configure, repeats) -> tuple[np.ndarray, float]:
    """Median render time over ``repeats`` renders, and the last image."""
    times = []
    for _ in range(repeats):
        scene = open_scene(bpy, name, size)
        configure(scene)
        image, seconds = render(bpy, scene, engine)
        times.append(seconds)
    return image, statistics.median(times)


def ours(preset: str, denoise: bool = False, **knobs):
    def configure(scene):
        scene.cycles.pixel_filter_type, scene.cycles.filter_width = "BOX", 1.0  # the reference's film
        scene.gpugi.mode = "GI"
        scene.gpugi.preset = preset
        scene.gpugi.denoise = denoise
        for key, value in knobs.items():
            setattr(scene.gpugi, key, value)
    return configure


def run_scene(bpy, name: str, args) -> list[dict]:
    ref = reference(bpy, name, args.size, args.reference_samples, args.mnee)
    rows = []
    # a first render builds and caches the kernels; it is not timed
    timed(bpy, name, args.size, "GPUGI", ours("DRAFT"), 1)
    for samples in CYCLES_SAMPLES:
        for denoise in (False, True):
            repeats = args.repeats if samples <= 64 else 1
            image, seconds = timed(bpy, name, args.size, "CYCLES",
                                   lambda s: cycles_settings(s, samples, denoise, mnee=args.mnee), repeats)
            rows.append(dict(scene=name, engine="Cycles" + (" denoised" if denoise else ""),
                             config=f"{samples} spp", seconds=seconds, **errors(image, ref)))
    for samples in CYCLES_ADAPTIVE:
        for denoise in (False, True):
            image, seconds = timed(bpy, name, args.size, "CYCLES",
                                   lambda s: cycles_settings(s, samples, denoise, adaptive=True, mnee=args.mnee),
                                   args.repeats)
            rows.append(dict(scene=name, engine="Cycles adaptive" + (" denoised" if denoise else ""),
                             config=f"{samples} spp", seconds=seconds, **errors(image, ref)))
    for denoise in (False, True):
        for preset in PRESETS:
            image, seconds = timed(bpy, name, args.size, "GPUGI", ours(preset, denoise), args.repeats)
            rows.append(dict(scene=name, engine="GPU GI preset" + (" denoised" if denoise else ""),
                             config=preset.title(), seconds=seconds, **errors(image, ref)))
    for knob, values in SWEEPS.items():
        for value in values:
            image, seconds = timed(bpy, name, args.size, "GPUGI", ours("PREVIEW", **{knob: value}), args.repeats)
            rows.append(dict(scene=name, engine="GPU GI sweep", config=f"{knob}={value}", seconds=seconds,
                             **errors(image, ref)))
    return rows


def target(rows: list[dict], metric: str = "error") -> str:
    """The issue's target: Cycles' 64-sample error (``metric``) at least 3x
    faster (aim 10x), by any GPU GI configuration."""
    c64 = next(r for r in rows if r["engine"] == "Cycles" and r["config"] == "64 spp")
    good = [r for r in rows if r["engine"].startswith("GPU GI") and r[metric] <= c64[metric]]
    if not good:
        best = min((r for r in rows if r["engine"].startswith("GPU GI")), key=lambda r: r[metric])
        return (f"{metric}: no GPU GI configuration reaches Cycles 64 spp's {c64[metric]:.3f} "
                f"(best {best[metric]:.3f}, {best['engine']} {best['config']}, {best['seconds']:.2f} s)")
    fastest = min(good, key=lambda r: r["seconds"])
    ratio = c64["seconds"] / fastest["seconds"]
    verdict = "met" if ratio >= 3 else "missed"
    return (f"{metric}: Cycles 64 spp {c64[metric]:.3f} in {c64['seconds']:.2f} s; GPU GI reaches it with "
            f"{fastest['engine']} {fastest['config']} in {fastest['seconds']:.2f} s: {ratio:.1f}x faster "
            f"(target 3x: {verdict}; aim 10x)")


def dominated_by(row: dict, rows: list[dict]) -> str:
    """The configuration that is both faster and closer than ``row`` by
    display error ('' when none: it is on the Pareto front)."""
    better = [r for r in rows if r["seconds"] < row["seconds"] and r["error"] < row["error"]]
    if not better:
        return ""
    best = min(better, key=lambda r: r["error"])
    return f"{best['engine']} {best['config']}"


def plot(rows: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = sorted({r["scene"] for r in rows})
    fig, axes = plt.subplots(1, len(scenes), figsize=(5 * len(scenes), 4.2), squeeze=False)
    styles = {"Cycles": "o-", "Cycles denoised": "s--", "Cycles adaptive": "o:", "Cycles adaptive denoised": "s:",
              "GPU GI preset": "D-", "GPU GI preset denoised": "D--", "GPU GI sweep": "x"}
    for ax, name in zip(axes[0], scenes):
        for engine, style in styles.items():
            pts = sorted((r["seconds"], r["error"]) for r in rows if r["scene"] == name and r["engine"] == engine)
            if pts:
                ax.loglog(*zip(*pts), style, label=engine)
        ax.set_title(name)
        ax.set_xlabel("render time (s)")
        ax.set_ylabel("relative RMSE of display values vs Cycles reference")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="+", default=["cornell_box", "box_torus", "caustics"])
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--reference-samples", type=int, default=4096)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--mnee", action="store_true", help="Cycles with manifold next-event estimation (caustics)")
    parser.add_argument("--quick", action="store_true", help="64 px, one repeat")
    parser.add_argument("--tag", default="", help="suffix of the result files, so a run of other scenes keeps them")
    args = parser.parse_args()
    if args.quick:
        args.size, args.repeats = 64, 1
    bpy = load_bpy()
    lines = [f"machine: {describe()}; {args.size}x{args.size} px; reference Cycles {args.reference_samples} spp"
             f"{' with MNEE (and every Cycles row)' if args.mnee else ''}; median of {args.repeats} renders (1 above 64 spp)"]
    print(lines[0], flush=True)
    rows = []
    for name in args.scenes:
        lines.append(f"{name}:")
        print(lines[-1], flush=True)
        scene_rows = run_scene(bpy, name, args)
        for r in scene_rows:
            front = ""
            if r["engine"].startswith("GPU GI preset"):
                beaten = dominated_by(r, scene_rows)
                front = f"   dominated by {beaten}" if beaten else "   Pareto front"
            lines.append(f"  {r['engine']:24s} {r['config']:22s} {r['seconds']:8.2f} s   display rel. RMSE "
                         f"{r['error']:.4f}   HDR-FLIP {r['flip']:.4f}   linear {r['linear']:.4f}{front}")
        lines += ["  " + target(scene_rows, "error"), "  " + target(scene_rows, "flip")]
        print("\n".join(lines[-len(scene_rows) - 2:]), flush=True)
        rows += scene_rows
    # the 64 px run is the README's first table; other sizes get their own files
    suffix = ("_quick" if args.quick else "" if args.size == 64 else f"_{args.size}") + (f"_{args.tag}" if args.tag else "")
    write_results(f"tradeoff{suffix}", rows, lines)
    figure = FIGURE.replace(".png", f"{suffix}.png")
    plot(rows, figure)
    print(f"plot: {figure}")


if __name__ == "__main__":
    main()
