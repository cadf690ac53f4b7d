"""RealPen: the feel and sound of a real pen on paper, for touch screens.

The library is numpy in, numpy out; the ``realpen`` command and the live app are thin shells
over it. Start with :func:`realpen.recording.load_recording` and
:func:`realpen.tactile.build_pattern`.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("realpen")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"
