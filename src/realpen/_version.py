"""The installed package's version, read on first use of ``realpen.__version__``.

A module of its own because :mod:`importlib.metadata` takes longer to import than the rest of
``import realpen`` (and the help of the ``realpen`` command) together.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("realpen")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"
