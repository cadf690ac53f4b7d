"""A sound loop in time and frequency, played on across its wrap, with the seam's figures."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes

from realpen.checks import require_number
from realpen.display.axes import axes_list, check_views, cyclic_spectrogram, db, side_colorbar

__all__ = ["plot_sound_loop", "VIEWS"]

VIEWS = ("waveform", "spectrogram")


def seam_caption(seam) -> str:
    """One line of the seam's figures (level jump and spectral flux at the wrap)."""
    if seam is None:
        return "seam not measured"
    parts = [f"level jump {seam.level_jump_db:.2f} dB"]
    if hasattr(seam, "flux_wrap_db"):
        flux = f"spectral flux {seam.flux_wrap_db:.2f} dB"
        if hasattr(seam, "flux_inside_median_db"):
            flux += (f" (inside the loop: median {seam.flux_inside_median_db:.2f}, "
                     f"p95 {seam.flux_inside_p95_db:.2f} dB)")
        parts.append(flux)
    return "wrap: " + ", ".join(parts)


def plot_sound_loop(loop, ax: Axes | Sequence[Axes] | None = None, *,
                    views: str | Sequence[str] = VIEWS, periods: int = 2,
                    fmax_hz: float = 16000.0, window_ms: float = 10.0) -> list[Axes]:
    """Two panels: the loop's waveform and spectrogram, played ``periods`` times in a row.

    The loop wraps where one period ends and the next begins; every wrap is marked with a
    dashed line, and the seam's figures (level jump at the wrap, spectral flux across it
    against the flux inside the loop) are in the title.

    Args:
        loop: a :class:`realpen.SoundLoop` (``samples``, ``rate``, ``seam``).
        ax: one Axes per view (a single Axes for a single view); None makes a new figure (not
            a pyplot one).
        views: which panels, in order: ``"waveform"`` and/or ``"spectrogram"``.
        periods: how many times the loop is drawn in a row (≥ 2 shows a wrap in the middle).
        fmax_hz: top of the spectrogram in Hz (at most the Nyquist frequency).
        window_ms: spectrogram window length in ms.

    Returns:
        The Axes drawn into, one per view.

    Example:
        >>> import numpy as np, realpen as rp
        >>> noise = np.random.default_rng(0).normal(0, 0.1, 48000)
        >>> loop = rp.find_loop(noise, rate=48000)
        >>> wave, spectrogram = rp.display.plot_sound_loop(loop)
        >>> spectrogram.get_xlabel(), spectrogram.get_ylabel()
        ('time (ms)', 'frequency (kHz)')
    """
    require_number("periods", periods, minimum=1)
    require_number("fmax_hz", fmax_hz, minimum=0.0, inclusive=False)
    require_number("window_ms", window_ms, minimum=0.0, inclusive=False)
    views = check_views(views, VIEWS)
    drawn = dict(zip(views, axes_list(ax, len(views), (8, 2.75 * len(views)), "ax")))
    x = np.asarray(loop.samples, dtype=np.float64).reshape(-1)
    rate = float(loop.rate)
    period_ms = len(x) / rate * 1000
    played = np.tile(x, int(periods))
    t_ms = np.arange(len(played)) / rate * 1000
    title = (f"sound loop of {period_ms:.0f} ms played {int(periods)}× (dashed: the wrap)\n"
             f"{seam_caption(getattr(loop, 'seam', None))}")
    if "waveform" in drawn:
        wave_ax = drawn["waveform"]
        wave_ax.plot(t_ms, played, lw=0.4, color="#1f4e79")
        wave_ax.set(xlim=(0, t_ms[-1]), xlabel="time (ms)", ylabel="amplitude (full scale)")
        if periods > 1:
            wave_ax.annotate("wrap", (period_ms, 1.0), xycoords=("data", "axes fraction"),
                             xytext=(3, -12), textcoords="offset points", color="#2a9d8f",
                             fontsize="small")
    if "spectrogram" in drawn:
        spec_ax = drawn["spectrogram"]
        freqs, times, power = cyclic_spectrogram(x, rate, window_ms, periods=int(periods))
        keep = freqs <= min(fmax_hz, rate / 2)
        level = db(power[keep])
        mesh = spec_ax.pcolormesh(times * 1000, freqs[keep] / 1000, level, shading="auto",
                                  cmap="magma", vmin=float(level.max()) - 80,
                                  vmax=float(level.max()), rasterized=True)
        spec_ax.set(xlim=(0, t_ms[-1]), xlabel="time (ms)", ylabel="frequency (kHz)")
        side_colorbar(spec_ax, mesh, "PSD (dB re FS²/Hz)")
    for axis in drawn.values():
        for k in range(1, int(periods)):
            axis.axvline(k * period_ms, color="#2a9d8f", lw=1.2, ls="--")
    next(iter(drawn.values())).set_title(title)
    return list(drawn.values())
