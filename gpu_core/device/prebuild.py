"""Programs compiled in a process of their own, into the disk cache.

PoCL compiles one program at a time per process (a first render's 8 s of
program builds on two cores took 8 s of CPU, threads or not), so
``Programs.build_all`` hands a share of the programs missing from the disk
cache to helper processes running this module and loads what they leave
there. A helper that fails leaves its programs to the render's process.

    python -m gpu_core.device.prebuild P:D < programs.json

``P:D`` names the device (platform and device index); the JSON holds
``[name, defines]`` pairs.
"""

from __future__ import annotations

import json
import sys


def main() -> None:
    from .select import get_device

    device = get_device(sys.argv[1])
    for name, defines in json.load(sys.stdin):
        device.programs.get(name, defines)


if __name__ == "__main__":
    main()
