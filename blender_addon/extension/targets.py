"""What one extension zip is built for: a Blender platform and a CPython ABI."""

from __future__ import annotations

from dataclasses import dataclass

# pip's --platform tags of the wheels each Blender platform can load: Blender's
# Linux builds run on glibc 2.28 and newer, its macOS builds on macOS 11 and newer.
WHEEL_PLATFORMS: dict[str, tuple[str, ...]] = {
    "linux-x64": tuple(f"manylinux_2_{minor}_x86_64" for minor in range(28, 16, -1)) + ("manylinux2014_x86_64",),
    "windows-x64": ("win_amd64",),
    "macos-arm64": ("macosx_11_0_arm64",),
}

# The Blender releases that embed each CPython: (first, first not supported).
BLENDER_RANGES: dict[str, tuple[str, str | None]] = {
    "cp311": ("4.2.0", "5.1.0"),
    "cp313": ("5.1.0", None),
}


@dataclass(frozen=True)
class Target:
    platform: str  # Blender's name, as the manifest's `platforms` lists it
    abi: str  # "cp311" or "cp313"

    @property
    def wheel_platforms(self) -> tuple[str, ...]:
        return WHEEL_PLATFORMS[self.platform]

    @property
    def python_version(self) -> str:
        """"3.11" for "cp311"."""
        return f"{self.abi[2]}.{self.abi[3:]}"

    @property
    def blender_range(self) -> tuple[str, str | None]:
        return BLENDER_RANGES[self.abi]

    @property
    def tag(self) -> str:
        """The zip name's part that says what it runs on, e.g. "linux_x64-cp311"."""
        return f"{self.platform.replace('-', '_')}-{self.abi}"


def all_targets(platforms=None, abis=None) -> list[Target]:
    """Every (platform, ABI) pair, or those of the given platforms and ABIs."""
    return [
        Target(platform, abi)
        for platform in (platforms or WHEEL_PLATFORMS)
        for abi in (abis or BLENDER_RANGES)
    ]
