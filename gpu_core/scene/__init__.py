"""The scene: its plain-numpy model, validation on entry, the tables the
kernels read, and the one device copy every kernel reads."""

from ..device.constants import (
    AREA_ELLIPSE,
    AREA_RECTANGLE,
    CAMERA_ORTHO,
    CAMERA_PERSP,
    FILTER_BLACKMAN_HARRIS,
    FILTER_BOX,
    FILTER_GAUSSIAN,
    LIGHT_AREA,
    LIGHT_POINT,
    LIGHT_SPOT,
    LIGHT_SUN,
    MATERIAL_GLASS,
    MATERIAL_GLOSSY,
    MATERIAL_PRINCIPLED,
    MATERIAL_TRANSPARENT,
    TEXTURE_LUMINANCE,
)
from .model import PARTS, Camera, Lights, Materials, Scene, ValidationReport, part_digests
from .validate import validate

__all__ = [
    "AREA_ELLIPSE", "AREA_RECTANGLE", "CAMERA_ORTHO", "CAMERA_PERSP", "FILTER_BLACKMAN_HARRIS", "FILTER_BOX",
    "FILTER_GAUSSIAN", "LIGHT_AREA", "LIGHT_POINT", "LIGHT_SPOT",
    "LIGHT_SUN", "MATERIAL_GLASS", "MATERIAL_GLOSSY", "MATERIAL_PRINCIPLED", "MATERIAL_TRANSPARENT", "PARTS", "TEXTURE_LUMINANCE", "Camera", "Lights", "Materials", "Scene", "ValidationReport", "part_digests", "validate",
]
