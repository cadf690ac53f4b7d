"""Figures into image files: the type a suffix names, reproducible bytes, atomic writes.

Every figure RealPen saves goes through here, so the same figure gives the same bytes (no date
in SVG or PDF metadata) and a failure leaves no half-written file.

May import: :mod:`realpen.errors`, :mod:`realpen.io` (and matplotlib).
"""

from __future__ import annotations

import contextlib
import io
import os
from collections.abc import Iterator, Sequence
from pathlib import Path

import matplotlib as mpl
from matplotlib.backend_bases import FigureCanvasBase
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.layout_engine import PlaceHolderLayoutEngine

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

    The figure's layout (its constrained or tight layout engine) is solved once, with the raster
    renderer at ``dpi``, and each type is then drawn once with that layout: a plain
    :meth:`~matplotlib.figure.Figure.savefig` would solve it again for every type and draw
    twice (a layout pass, then the drawing). Axis labels without text are not placed beside
    their tick labels meanwhile (they draw nothing and take no room). The images are the ones
    ``savefig`` gives with ``png`` first; the figure keeps its layout engine and labels.

    Args:
        figure: the figure to render.
        kinds: image types as :func:`image_kinds` gives them.
        dpi: resolution of raster types in dots per inch.

    Returns:
        The bytes of each type, in the order of ``kinds``.
    """
    images = {}
    with _empty_labels_unplaced(figure), _layout_solved(figure, dpi) as solved:
        for kind in kinds:
            buffer = io.BytesIO()
            figure.savefig(buffer, format=kind, dpi=dpi, metadata=image_metadata(kind))
            images[kind] = buffer.getvalue()
            if not solved:
                # The first save laid the figure out; keep that layout for the other types.
                figure.set_layout_engine("none")
    return images


@contextlib.contextmanager
def _empty_labels_unplaced(figure: Figure) -> Iterator[None]:
    """Within: the axis labels of ``figure`` that have no text keep their place.

    matplotlib places every axis label beside its axis's tick labels, measuring them again, at
    each layout pass and each drawing; a label without text is never drawn and takes no room,
    so where it is changes nothing (in a grid of panels with the figure's own axis labels,
    that is a tenth of the rendering). Uses matplotlib's ``Axis._autolabelpos`` (a label's
    automatic placement, off after ``set_label_coords``) and leaves every label as it was."""
    unplaced = [axis for ax in figure.axes for axis in (ax.xaxis, ax.yaxis)
                if not axis.label.get_text() and getattr(axis, "_autolabelpos", None) is True]
    for axis in unplaced:
        axis._autolabelpos = False
    try:
        yield
    finally:
        for axis in unplaced:
            axis._autolabelpos = True


@contextlib.contextmanager
def _layout_solved(figure: Figure, dpi: int) -> Iterator[bool]:
    """Within: ``figure`` laid out by its layout engine at ``dpi`` and without the engine, so
    that saving draws it once; yields False (nothing done) when it has no engine to solve or
    the user's rcParams would put one back in its place. The engine returns on leaving."""
    engine = figure.get_layout_engine()
    if engine is None or isinstance(engine, PlaceHolderLayoutEngine) or \
            mpl.rcParams["figure.autolayout"] or mpl.rcParams["figure.constrained_layout.use"]:
        try:
            yield False
        finally:
            if engine is not None:
                figure.set_layout_engine(engine)
        return
    canvas, original_dpi = figure.canvas, figure.dpi
    FigureCanvasAgg(figure)  # the renderer savefig's PNG would lay the figure out with
    try:
        figure.dpi = dpi
        engine.execute(figure)
    finally:
        figure.dpi = original_dpi
        figure.set_canvas(canvas)
    figure.set_layout_engine(None)
    try:
        yield True
    finally:
        figure.set_layout_engine(engine)


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
