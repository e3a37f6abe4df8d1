"""The add-on as Blender extension zips, one per platform and Python ABI
(``python -m blender_addon build-extension``). Repository tooling: the zips
do not carry it."""


class BuildError(Exception):
    """A zip cannot be built; the message says what to do."""
