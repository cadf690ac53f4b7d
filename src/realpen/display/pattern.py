"""A tactile pattern in time and as a spectrogram (the method's Figure 8)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes

from realpen.checks import require_number
from realpen.display.axes import axes_list, check_views, cyclic_spectrogram, db, side_colorbar

__all__ = ["plot_pattern", "VIEWS"]

VIEWS = ("time", "spectrogram")


def pattern_signal(pattern, rate: float | None = None) -> tuple[np.ndarray, float]:
    """One loop of the pattern and its rate in Hz: its own samples, or rendered at ``rate``."""
    if rate is None:
        return np.asarray(pattern.samples, dtype=np.float64).reshape(-1), float(pattern.rate)
    return np.asarray(pattern.render(rate), dtype=np.float64).reshape(-1), float(rate)


def plot_pattern(pattern, ax: Axes | Sequence[Axes] | None = None, *,
                 views: str | Sequence[str] = VIEWS, rate: float | None = None,
                 fmax_hz: float | None = None, window_ms: float = 25.0) -> list[Axes]:
    """The looping pattern in time and as a spectrogram, sub-pattern boundaries marked.

    Like the method's Figure 8: the drive signal over one loop (1500 ms for the study
    conditions) and its short-time spectrum, where the fluctuation from one 100 ms sub-pattern
    to the next shows. Boundaries between sub-patterns are dotted lines; the spectrogram is
    computed across the loop wrap, as the pattern plays.

    Args:
        pattern: a :class:`realpen.TactilePattern` (or anything with ``samples``, ``rate``,
            ``render(rate)``, ``subpattern_ms`` and ``max_frequency_hz``).
        ax: one Axes per view (a single Axes for a single view). None makes a new figure (not a
            pyplot one).
        views: which panels, in order: ``"time"`` and/or ``"spectrogram"``.
        rate: render the pattern at this rate in Hz (default: the pattern's own rate).
        fmax_hz: top of the spectrogram in Hz (default: 1.2 × the highest component, at most
            Nyquist).
        window_ms: spectrogram window length in ms.

    Returns:
        The Axes drawn into, one per view.

    Example:
        >>> import realpen as rp
        >>> from realpen.examples import example_recording_path
        >>> pattern = rp.tactile_pattern(rp.load_recording(example_recording_path()))
        >>> wave, spectrogram = rp.display.plot_pattern(pattern)
        >>> spectrogram.get_ylabel()
        'frequency (Hz)'
    """
    views = check_views(views, VIEWS)
    require_number("window_ms", window_ms, minimum=0.0, inclusive=False)
    drawn = axes_list(ax, len(views), (8, 2.8 * len(views)), "ax")
    x, rate = pattern_signal(pattern, rate)
    t_ms = np.arange(len(x)) / rate * 1000
    total_ms = len(x) / rate * 1000
    sub_ms = float(pattern.subpattern_ms)
    boundaries = np.arange(sub_ms, total_ms - 1e-6, sub_ms)
    count = int(round(total_ms / sub_ms))
    what = (f"{count} sub-patterns of {sub_ms:g} ms" if count > 1
            else f"one {sub_ms:g} ms pattern")
    for view, ax in zip(views, drawn):
        if view == "time":
            ax.plot(t_ms, x, lw=0.5, color="#1f4e79")
            ax.set(ylabel="drive (full scale)", title=f"tactile pattern: {what}, looping")
        else:
            freqs, times, power = cyclic_spectrogram(x, rate, window_ms)
            top = fmax_hz or 1.2 * float(pattern.max_frequency_hz)
            keep = freqs <= min(top, rate / 2)
            level = db(power[keep])
            mesh = ax.pcolormesh(times * 1000, freqs[keep], level, shading="auto",
                                 cmap="magma", vmin=float(level.max()) - 60,
                                 vmax=float(level.max()), rasterized=True)
            side_colorbar(ax, mesh, "PSD (dB re FS²/Hz)")
            ax.set(ylabel="frequency (Hz)",
                   title=f"spectrogram ({window_ms:g} ms window, across the loop wrap)")
        for boundary in boundaries:
            ax.axvline(boundary, color="#e9c46a" if view == "spectrogram" else "#c44",
                       lw=0.6, ls=":", alpha=0.9)
        ax.set(xlim=(0, total_ms), xlabel="time (ms)")
    return drawn

