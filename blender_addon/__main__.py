"""``python -m blender_addon``: the command line (see cli.py), or
``python -m blender_addon build-extension`` (see extension/build.py)."""

import sys

if sys.argv[1:2] == ["build-extension"]:
    from .extension.build import main

    sys.exit(main(sys.argv[2:]))

from .cli import main  # noqa: E402

sys.exit(main())
