"""Every kernel program read by clang's own analyses for what OpenCL C leaves
undefined: a value read before it is written, an index past a private
array's end, a division by a zero constant, a constant expression that
overflows, a function that ends without its value, a variable written
twice between sequence points (shifts are defined in OpenCL C: their
count is taken modulo the operand's width). Drivers compile such code as
they like (PoCL's compiler and NVIDIA's may differ), so none is allowed.
Each program is read as a render builds it (its defines from the plan of
a GI render with a caustic map), and again with every optional feature on
and PoCL's header of inlined builtins before it; the GPU form of the
kd-tree build (lanes sharing a node's SAH search) besides."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import clang.cindex as cindex
from scenes_py import box_scene

from gpu_core.accel import kdtree_build, kdtree_overlay
from gpu_core.device.programs import INCLUDE_ROOT, build_options, load_source, with_inline_builtins
from gpu_core.gi import cut
from gpu_core.photons import reweight
from gpu_core.plan import plan
from gpu_core.settings import RenderSettings

GI = RenderSettings(mode="gi", samples=2, global_photons=20_000, caustic_photons=20_000, photon_k=20,
                    cache_seeds=60, gather_rays=16)
# the analyses' warnings: each names behaviour OpenCL C leaves undefined
UNDEFINED = {"-Wuninitialized", "-Wsometimes-uninitialized", "-Wconditional-uninitialized", "-Warray-bounds",
             "-Wdivision-by-zero", "-Winteger-overflow", "-Wreturn-type", "-Wunsequenced"}
# every optional part of the programs compiled in (scene features, image passes, the glossy cut lookup)
FEATURES = {"SCENE_HAS_TEXTURES": 1, "SCENE_HAS_ALPHA": 1, "SCENE_HAS_MIX": 1, "SCENE_HAS_TANGENTS": 1,
            "IMAGE_GI": 1, "IMAGE_LIGHT_PASSES": 1, "IMAGE_GLOSSY_CUT": 1, **cut.image_lookup_defines()}
# programs that only tests and checks build
CHECK_PROGRAMS = [("accel/kdtree_query.cl", {}), ("shading/bsdf_check.cl", {})]


def opencl_header() -> Path:
    """The OpenCL C declarations PoCL's compiler reads (pocl-binary-distribution's copy)."""
    spec = importlib.util.find_spec("pocl_binary_distribution")
    return Path(spec.origin).parent / ".libs" / "share" / "pocl" / "include"


def place(source: str, line: int) -> str:
    """'file:line' of a line of a program's source, by its #line markers (load_source)."""
    lines = source.splitlines()
    for index in range(min(line, len(lines)) - 1, -1, -1):
        if lines[index].startswith("#line "):
            _, number, name = lines[index].split(" ", 2)
            return f"{name.strip(chr(34))}:{int(number) + line - index - 2}"
    return f"line {line}"


def analyse(source: str, options) -> list[tuple[str, str, str]]:
    """clang's diagnostics of an OpenCL C 1.2 ``source`` built with
    ``options``: (warning option or 'error', file:line, message) for every
    error and every warning of UNDEFINED."""
    args = ["-x", "cl", "-cl-std=CL1.2", "-isystem", str(opencl_header()), "-include", "opencl-c.h",
            *sorted(UNDEFINED), *(o for o in options if o.startswith("-D"))]
    unit = cindex.Index.create().parse("program.cl", args=args, unsaved_files=[("program.cl", source)])
    found = []
    for d in unit.diagnostics:
        if d.severity >= cindex.Diagnostic.Error or d.option in UNDEFINED:
            option = d.option if d.severity < cindex.Diagnostic.Error else "error"
            found.append((option, place(source, d.location.line), d.spelling))
    return found


def programs(device) -> list[tuple[str, dict]]:
    """The programs a GI render with a caustic map builds, the viewport's
    edits' programs, the kd-tree build's GPU form and the checks' programs."""
    chosen = plan(box_scene(mirror=True), GI, device=device).programs
    chosen += kdtree_overlay.programs() + reweight.programs() + kdtree_build.programs(device, sah_lanes=4)
    return chosen + CHECK_PROGRAMS


def test_the_analyses_find_what_they_look_for():
    source = """
    int first(int a) { int x; if (a) x = 1; return x; }
    int second(int a) { if (a) return 1; }
    __kernel void k(__global int *out, int i) {
        int y[4]; y[0] = 1;
        out[0] = y[4] + first(i) / 0 + second(i) + 2147483647 * 2;
        i = i++ + 1; out[1] = i;
        int z; out[2] = z;
    }
    """
    flagged = {option for option, _, _ in analyse(source, ())}
    assert flagged == UNDEFINED - {"-Wconditional-uninitialized"}  # (which needs a value clang cannot follow)
    assert analyse("__kernel void k(__global int *out) { out[0] = ; }", ())[0][0] == "error"


def test_every_program_is_read_without_undefined_behaviour(device):
    read, found = set(), set()
    for name, defines in programs(device):
        read.add(name)
        found |= set(analyse(load_source(name), build_options(defines)))
        found |= set(analyse(with_inline_builtins(load_source(name)), build_options({**defines, **FEATURES})))
    assert not found, "\n".join(f"{where}: {option}: {message}" for option, where, message in sorted(found))
    assert {str(p.relative_to(INCLUDE_ROOT)) for p in INCLUDE_ROOT.rglob("*.cl")} <= read  # every program was read
