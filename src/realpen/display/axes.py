"""Helpers shared by the display modules: axes to draw into, spectrograms, dB.

Figures are made with :class:`matplotlib.figure.Figure` directly, never with ``pyplot``, so a
figure made here is not registered with pyplot's figure manager, no backend is chosen and no
window opens. In a notebook, the figure shows when it is the cell's value (``ax.figure``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from realpen.errors import ParameterError

__all__ = ["new_axes", "axes_list", "check_views", "db", "cyclic_spectrogram", "side_colorbar", "hz_ticks"]

_TINY = 1e-30


def new_axes(count: int, figsize: tuple[float, float]) -> list[Axes]:
    """``count`` axes stacked vertically in a new, constrained-layout figure (not pyplot's)."""
    figure = Figure(figsize=figsize, layout="constrained")
    made = figure.subplots(count, 1, squeeze=False)[:, 0]
    return list(made)


def axes_list(axes: Axes | Sequence[Axes] | None, count: int, figsize: tuple[float, float],
              parameter: str = "axes") -> list[Axes]:
    """The caller's axes as a list of ``count`` (a single Axes counts as one), or new ones."""
    if axes is None:
        return new_axes(count, figsize)
    given = [axes] if isinstance(axes, Axes) else list(np.ravel(np.asarray(axes, dtype=object)))
    if len(given) != count or not all(isinstance(a, Axes) for a in given):
        raise ParameterError(parameter, f"needs {count} matplotlib Axes, got {len(given)} "
                                        f"object(s)")
    return given


def check_views(views: str | Sequence[str], known: tuple[str, ...]) -> tuple[str, ...]:
    """The requested panels as a tuple, each one of ``known``; one name alone is one view."""
    views = (views,) if isinstance(views, str) else tuple(views)
    if not views:
        raise ParameterError("views", "needs at least one view")
    for view in views:
        if view not in known:
            raise ParameterError("views", f"unknown view {view!r} (choose from {', '.join(known)})")
    return views


def db(power: np.ndarray, reference: float = 1.0) -> np.ndarray:
    """10·log10(power / reference), with silence floored far below (not −inf)."""
    return 10 * np.log10(np.maximum(np.asarray(power, dtype=np.float64), _TINY) / reference)


def cyclic_spectrogram(x: np.ndarray, rate: float, window_ms: float, periods: int = 1
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Power spectrogram of a looping signal, the loop wrap included.

    The signal is repeated ``periods`` times and padded at both ends with its own continuation,
    so the first and last frames see what a listener hears when the loop plays on.

    Returns:
        ``(frequencies_hz, times_s, power)``; ``power`` has shape (frequencies, times), in the
        signal's unit squared per Hz.
    """
    from scipy import signal  # display is already heavy; scipy only when drawing

    x = np.asarray(x, dtype=np.float64)
    nperseg = max(16, min(len(x), int(round(window_ms * rate / 1000.0))))
    hop = max(1, nperseg // 8)
    pad = nperseg // 2
    repeated = np.tile(x, periods + 2)[len(x) - pad: len(x) * (periods + 1) + pad]
    freqs, times, power = signal.spectrogram(repeated, rate, window="hann", nperseg=nperseg,
                                             noverlap=nperseg - hop, nfft=4 * nperseg,
                                             detrend=False, mode="psd")
    return freqs, times - pad / rate, power


def side_colorbar(ax: Axes, mappable, label: str):
    """A slim colour bar just right of ``ax`` that takes no width from it.

    Drawn in an inset axes, so panels stacked in a column keep the same width and their time
    axes stay aligned (``Figure.colorbar(ax=...)`` would shrink only this one).
    """
    holder = ax.inset_axes((1.01, 0.0, 0.018, 1.0))
    bar = ax.figure.colorbar(mappable, cax=holder)
    bar.set_label(label)
    return bar


def hz_ticks(ax: Axes, low: float, high: float) -> None:
    """Plain-number ticks (20, 50, 100, 200, ...) on a logarithmic frequency axis."""
    from matplotlib.ticker import FixedLocator, NullFormatter, ScalarFormatter

    decades = 10.0 ** np.arange(np.floor(np.log10(low)), np.ceil(np.log10(high)) + 1)
    ticks = [v for d in decades for v in (d, 2 * d, 5 * d) if low <= v <= high]
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    formatter = ScalarFormatter()
    formatter.set_scientific(False)
    ax.xaxis.set_major_formatter(formatter)
    ax.xaxis.set_minor_formatter(NullFormatter())
