"""Errors gpu_core raises; each carries a message a user can act on."""

from typing import Callable


class GpuGiError(Exception):
    """Base class of every error gpu_core raises on purpose."""


class DeviceError(GpuGiError):
    """No usable OpenCL device, or a kernel program failed to build."""


class SceneError(GpuGiError):
    """The scene cannot be rendered as given (after validation)."""


class BudgetError(GpuGiError):
    """A buffer would exceed the device memory budget."""


class RenderCancelled(GpuGiError):
    """The caller asked to stop (Esc in Blender) between two kernel batches."""


def check_stop(should_stop: Callable[[], bool] | None) -> None:
    """RenderCancelled when the caller asked to stop."""
    if should_stop is not None and should_stop():
        raise RenderCancelled("render cancelled")
