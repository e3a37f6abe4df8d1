"""The add-on registers inside the bpy module, as batch jobs and tests use it."""

import ast
import os
import tomllib
from types import SimpleNamespace

import blender_addon
from conftest import ROOT

ADDON_DIR = os.path.join(ROOT, "blender_addon")


def _addon_sources():
    for folder, _, files in os.walk(ADDON_DIR):
        for name in files:
            if name.endswith(".py"):
                path = os.path.join(folder, name)
                with open(path) as f:
                    yield os.path.relpath(path, ADDON_DIR), ast.parse(f.read())


def _imported_modules(tree, top_level_only):
    nodes = tree.body if top_level_only else ast.walk(tree)
    for node in nodes:
        if isinstance(node, ast.Import):
            yield from (alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module.split(".")[0]


def test_engine_is_registered_with_the_expected_flags(bpy_module):
    bpy = bpy_module
    engine = bpy.types.RenderEngine.bl_rna_get_subclass_py("GPUGI")
    assert engine is not None
    assert engine.bl_label == "GPU GI"
    assert engine.bl_use_preview is True
    assert engine.bl_use_shading_nodes_custom is False


def test_settings_live_at_scene_gpugi(bpy_empty):
    scene = bpy_empty.context.scene
    scene.render.engine = "GPUGI"
    assert scene.render.engine == "GPUGI"
    assert scene.gpugi.samples == 16
    settings = scene.gpugi.render_settings()
    assert settings.samples == 16 and settings.max_bounces == 8


def test_scene_settings_reach_the_render_settings(bpy_empty):
    gpugi = bpy_empty.context.scene.gpugi
    gpugi.samples, gpugi.preview_samples, gpugi.max_bounces, gpugi.diffuse_bounces = 5, 2, 3, 4
    gpugi.clamp, gpugi.seed = 7.5, 11
    final = gpugi.render_settings(preview=False, transparent=True)
    preview = gpugi.render_settings(preview=True)
    assert (final.samples, final.max_bounces, final.diffuse_bounces, final.clamp, final.seed) == (5, 3, 4, 7.5, 11)
    assert final.transparent_background is True and preview.transparent_background is False
    assert preview.samples == 2


def test_denoising_is_on_for_renders_and_off_for_the_viewport_by_default_as_in_cycles(bpy_empty):
    gpugi = bpy_empty.context.scene.gpugi
    assert (gpugi.denoise, gpugi.preview_denoise, gpugi.denoise_quality) == (True, False, "HIGH")
    assert gpugi.render_settings().denoise is True
    assert gpugi.render_settings(preview=True).denoise is False
    gpugi.preview_denoise, gpugi.denoise_quality = True, "FAST"
    preview = gpugi.render_settings(preview=True)
    assert preview.denoise is True and preview.denoise_quality == "fast"


def test_stock_panels_are_enabled_for_the_engine(bpy_module):
    bpy = bpy_module
    for name in ("RENDER_PT_format", "RENDER_PT_output", "DATA_PT_lens", "DATA_PT_context_light", "DATA_PT_spot"):
        assert "GPUGI" in getattr(bpy.types, name).COMPAT_ENGINES, name
    assert "GPUGI" not in getattr(bpy.types, "VIEWLAYER_PT_filter").COMPAT_ENGINES


def test_material_world_and_light_panels_that_apply_are_enabled(bpy_module):
    bpy = bpy_module
    for name in ("EEVEE_MATERIAL_PT_context_material", "EEVEE_MATERIAL_PT_surface", "EEVEE_WORLD_PT_surface",
                 "DATA_PT_EEVEE_light"):
        assert "GPUGI" in getattr(bpy.types, name).COMPAT_ENGINES, name
    # settings this engine does not read stay hidden, and no Cycles panel is touched
    for name in ("EEVEE_MATERIAL_PT_volume", "DATA_PT_EEVEE_light_shadow", "CYCLES_RENDER_PT_sampling",
                 "CYCLES_LIGHT_PT_light"):
        assert "GPUGI" not in getattr(bpy.types, name).COMPAT_ENGINES, name


def test_own_panels_show_only_for_this_engine(bpy_module):
    from blender_addon.ui import PANELS

    for panel in PANELS:
        assert panel.poll(SimpleNamespace(engine="GPUGI"))
        assert not panel.poll(SimpleNamespace(engine="CYCLES"))


def test_unregister_and_register_again(bpy_module):
    bpy = bpy_module
    blender_addon.unregister()
    try:
        assert bpy.types.RenderEngine.bl_rna_get_subclass_py("GPUGI") is None
        assert not hasattr(bpy.types.Scene, "gpugi")
        assert "GPUGI" not in bpy.types.RENDER_PT_format.COMPAT_ENGINES
        assert "GPUGI" not in bpy.types.EEVEE_MATERIAL_PT_surface.COMPAT_ENGINES
        blender_addon.unregister()  # a second call is harmless
    finally:
        blender_addon.register()
        blender_addon.register()  # a second call is harmless
    assert bpy.types.RenderEngine.bl_rna_get_subclass_py("GPUGI") is not None
    assert hasattr(bpy.types.Scene, "gpugi")
    assert "GPUGI" in bpy.types.RENDER_PT_format.COMPAT_ENGINES


def test_manifest_and_bl_info_declare_blender_4_2_or_newer():
    with open(os.path.join(ADDON_DIR, "blender_manifest.toml"), "rb") as f:
        manifest = tomllib.load(f)
    for key in ("schema_version", "id", "version", "name", "tagline", "maintainer", "type", "license"):
        assert manifest.get(key), key
    assert manifest["type"] == "add-on"
    assert tuple(int(p) for p in manifest["blender_version_min"].split(".")) >= (4, 2, 0)
    assert len(manifest["tagline"]) <= 64 and not manifest["tagline"].endswith((".", "!", "?"))
    assert blender_addon.bl_info["blender"] >= (4, 2, 0)
    assert blender_addon.bl_info["name"] == manifest["name"]


def test_gpu_module_is_imported_only_inside_functions():
    # gpu drawing is unavailable in background mode: no module-level import may need it
    for name, tree in _addon_sources():
        assert not {"gpu", "gpu_extras"} & set(_imported_modules(tree, top_level_only=True)), name


def test_addon_never_launches_kernels_itself():
    for name, tree in _addon_sources():
        assert "pyopencl" not in set(_imported_modules(tree, top_level_only=False)), name


class RecordingLayout:
    """Enough of UILayout for a panel's draw(): checks every drawn property exists."""

    def __init__(self):
        self.drawn: list[str] = []
        self.use_property_split = False

    def column(self, **kwargs):
        return self

    def row(self, **kwargs):
        return self

    def label(self, **kwargs):
        pass

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, name
        self.drawn.append(name)


def test_own_panels_draw_existing_settings(bpy_empty):
    from blender_addon.ui import PANELS

    scene = bpy_empty.context.scene
    scene.gpugi.mode = "GI"
    context = SimpleNamespace(scene=scene, view_layer=scene.view_layers[0], engine="GPUGI")
    drawn = []
    for panel in PANELS:
        layout = RecordingLayout()
        panel.draw(SimpleNamespace(layout=layout), context)
        drawn += layout.drawn
    assert {"mode", "preset", "samples", "preview_samples", "max_bounces", "diffuse_bounces", "clamp", "seed",
            "device", "film_transparent", "global_photons", "caustic_photons", "photon_k", "cache_seeds",
            "gather_rays", "gi_subpixels", "cut_delta", "cache_alpha", "denoise", "preview_denoise",
            "denoise_quality", "noise_threshold", "min_samples"} <= set(drawn)
    # the Passes panel: every toggle of a pass this engine writes
    assert {"use_pass_z", "use_pass_normal", "use_pass_diffuse_direct", "use_pass_glossy_indirect",
            "use_pass_transmission_direct", "use_pass_emit", "use_pass_environment", "use_pass_caustics",
            "denoising_store_passes"} <= set(drawn)
