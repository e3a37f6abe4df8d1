"""GPU GI core: scene, OpenCL device and the rendering pipeline. Never imports bpy."""

from .errors import BudgetError, DeviceError, GpuGiError, RenderCancelled, SceneError

__all__ = ["BudgetError", "DeviceError", "GpuGiError", "RenderCancelled", "SceneError"]
