"""Figures into image files: the type a suffix names, reproducible bytes, atomic writes.

Every figure RealPen saves goes through here, so the same figure gives the same bytes (no date
in SVG or PDF metadata) and a failure leaves no half-written file.

May import: :mod:`realpen.errors`, :mod:`realpen.io` (and matplotlib).
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from pathlib import Path

from matplotlib.backend_bases import FigureCanvasBase
from matplotlib.figure import Figure

from realpen.errors import ParameterError, fail
from realpen.io.files import atomic_path

__all__ = ["FORMATS", "DPI", "image_kind", "image_kinds", "image_metadata", "figure_images",
           "save_figure"]

FORMATS = ("png", "svg")
"""The image types a study's figures are saved in."""
DPI = 150
"""Resolution of raster images in dots per inch."""


def image_kind(target: str | os.PathLike) -> str:
    """The image type matplotlib writes for ``target``'s suffix (``"png"``, ``"svg"`` …).

    Raises:
        RealPenError: a suffix matplotlib cannot write, named with the types it can.

    >>> image_kind("power.SVG")
    'svg'
    """
    kind = Path(target).suffix.lower().lstrip(".")
    supported = FigureCanvasBase.get_supported_filetypes()
    if kind not in supported:
        raise fail(target, f"unknown image type '.{kind}' (use one of "
                           f"{', '.join('.' + k for k in sorted(supported))})")
    return kind


def image_kinds(formats: Sequence[str], dpi: int) -> list[str]:
    """``formats`` as matplotlib's type names (``".PNG"`` → ``"png"``), checked with ``dpi``.

    Raises:
        ParameterError: no format, one matplotlib cannot write (``formats``), or ``dpi`` not a
            whole number ≥ 10.
    """
    kinds = [str(kind).lower().lstrip(".") for kind in formats]
    supported = FigureCanvasBase.get_supported_filetypes()
    for kind in kinds:
        if kind not in supported:
            raise ParameterError("formats", f"unknown image type {kind!r} (choose from "
                                            f"{', '.join(sorted(supported))})")
    if not kinds:
        raise ParameterError("formats", "needs at least one image type")
    if isinstance(dpi, bool) or not isinstance(dpi, int) or dpi < 10:
        raise ParameterError("dpi", f"must be a whole number >= 10, got {dpi!r}")
    return kinds


def image_metadata(kind: str) -> dict:
    """The ``metadata`` for :meth:`matplotlib.figure.Figure.savefig` of type ``kind``."""
    # No date in the files: the same figure gives the same bytes.
    return {"Date": None} if kind in ("svg", "pdf") else {}


def figure_images(figure: Figure, kinds: Sequence[str], *, dpi: int = DPI) -> dict[str, bytes]:
    """``figure`` rendered in memory as each image type of ``kinds`` (``{"png": b"…"}``).

    ``kinds`` as :func:`image_kinds` gives them; ``dpi`` in dots per inch (raster types).
    """
    images = {}
    for kind in kinds:
        buffer = io.BytesIO()
        figure.savefig(buffer, format=kind, dpi=dpi, metadata=image_metadata(kind))
        images[kind] = buffer.getvalue()
        # The first save laid the figure out; keep that layout for the other formats rather
        # than solve it again (a third of the time a figure takes to save).
        figure.set_layout_engine("none")
    return images


def save_figure(figure: Figure, target: str | os.PathLike, *, dpi: int = DPI) -> Path:
    """Write ``figure`` into an image file whose type its suffix names, atomically.

    Args:
        figure: the figure to save.
        target: the file (``.png``, ``.svg`` or another type matplotlib writes).
        dpi: resolution of raster formats in dots per inch.

    Returns:
        The path written.

    Raises:
        RealPenError: an image type matplotlib cannot write (named by the suffix).
    """
    target = Path(target)
    kind = image_kind(target)
    with atomic_path(target) as tmp:
        figure.savefig(tmp, format=kind, dpi=dpi, metadata=image_metadata(kind))
    return target
