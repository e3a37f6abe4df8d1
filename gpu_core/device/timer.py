"""Milliseconds per named stage, the one stage timer of gpu_core."""

from __future__ import annotations

import time
from contextlib import contextmanager


class StageTimer:
    """Accumulates wall milliseconds per stage name, in the order stages first ran.

    With a ``queue``, each stage ends by waiting for it, so the time of the
    kernels it enqueued is counted in that stage and not the next.
    """

    def __init__(self, queue=None):
        self.queue = queue
        self.ms: dict[str, float] = {}

    @contextmanager
    def stage(self, name: str):
        start = time.perf_counter()
        try:
            yield
        finally:
            if self.queue is not None:
                self.queue.finish()
            self.ms[name] = self.ms.get(name, 0.0) + (time.perf_counter() - start) * 1e3

    def add(self, other: "StageTimer | dict", prefix: str = "") -> None:
        """Add another timer's stages (or a dict of them) into this one."""
        items = other.ms.items() if isinstance(other, StageTimer) else other.items()
        for name, ms in items:
            self.ms[prefix + name] = self.ms.get(prefix + name, 0.0) + ms
