"""The add-on registers inside the bpy module, as batch jobs and tests use it."""

import blender_addon


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


def test_stock_panels_are_enabled_for_the_engine(bpy_module):
    bpy = bpy_module
    for name in ("RENDER_PT_format", "RENDER_PT_output", "DATA_PT_lens", "DATA_PT_context_light"):
        panel = getattr(bpy.types, name, None)
        if panel is not None and hasattr(panel, "COMPAT_ENGINES"):
            assert "GPUGI" in panel.COMPAT_ENGINES, name
    assert "GPUGI" not in getattr(bpy.types, "VIEWLAYER_PT_filter").COMPAT_ENGINES


def test_unregister_and_register_again(bpy_module):
    bpy = bpy_module
    blender_addon.unregister()
    assert bpy.types.RenderEngine.bl_rna_get_subclass_py("GPUGI") is None
    assert not hasattr(bpy.types.Scene, "gpugi")
    blender_addon.register()
    blender_addon.register()  # a second call is harmless
    assert bpy.types.RenderEngine.bl_rna_get_subclass_py("GPUGI") is not None
    assert hasattr(bpy.types.Scene, "gpugi")
