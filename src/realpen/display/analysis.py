"""The principal frequencies of every unit sequence, as the method's Figure 4b."""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes

from realpen.display.axes import axes_list, db, side_colorbar

__all__ = ["plot_analysis"]

FLOOR_DB = -60.0  # peaks further below the strongest are drawn at the smallest size


def plot_analysis(analysis, ax: Axes | None = None, *, floor_db: float = FLOOR_DB,
                  colorbar: bool = True, cmap: str = "viridis") -> Axes:
    """Principal frequencies per unit: unit time on x, frequency on y, power as size and colour.

    Each unit sequence contributes its top-N peaks at the unit's centre time; a marker's size
    and colour give the peak's power in dB relative to the strongest peak of the recording.
    The units selected for the pattern are shaded and their markers outlined.

    Args:
        analysis: a :class:`realpen.dsp.spectrum.Analysis` (what :func:`realpen.analyze`
            returns).
        ax: the Axes to draw into; None makes a new figure (not a pyplot one).
        floor_db: power (dB re the strongest peak) drawn at the smallest size and the bottom
            of the colour scale.
        colorbar: add a colour bar for the power beside ``ax``.
        cmap: matplotlib colour map name.

    Returns:
        The Axes drawn into.

    Example:
        >>> import realpen as rp
        >>> from realpen.examples import example_recording_path
        >>> analysis = rp.analyze(rp.load_recording(example_recording_path()))
        >>> ax = rp.display.plot_analysis(analysis)
        >>> ax.get_ylabel()
        'frequency (Hz)'
    """
    (ax,) = axes_list(ax, 1, (8, 4), parameter="ax")
    unit_s = analysis.unit_ms / 1000.0
    centres = np.asarray(analysis.starts_s, dtype=np.float64) + unit_s / 2
    freqs = np.asarray(analysis.frequencies_hz, dtype=np.float64)
    powers = np.asarray(analysis.powers, dtype=np.float64)
    strongest = float(np.nanmax(powers)) if np.isfinite(powers).any() else 1.0
    level = np.clip(db(np.nan_to_num(powers, nan=0.0), strongest), floor_db, 0.0)
    times = np.broadcast_to(centres[:, None], freqs.shape)
    keep = np.isfinite(freqs)
    selected = np.zeros(len(centres), dtype=bool)
    selected[np.asarray(analysis.selected, dtype=int)] = True
    chosen = keep & selected[:, None]

    sizes = 4 + 60 * (1 - level / floor_db)  # 4 pt² at the floor, 64 pt² at the strongest
    order = np.argsort(level[keep])  # the strongest drawn last, on top
    points = ax.scatter(times[keep][order], freqs[keep][order], s=sizes[keep][order],
                        c=level[keep][order], cmap=cmap, vmin=floor_db, vmax=0.0,
                        linewidths=0, zorder=2)
    if chosen.any():
        ax.scatter(times[chosen], freqs[chosen], s=sizes[chosen], facecolors="none",
                   edgecolors="black", linewidths=0.6, zorder=3,
                   label=f"selected: {int(selected.sum())} units")
        first = float(analysis.starts_s[int(np.min(analysis.selected))])
        last = float(analysis.starts_s[int(np.max(analysis.selected))]) + unit_s
        ax.axvspan(first, last, color="#f2c14e", alpha=0.25, lw=0, zorder=1)
        ax.legend(loc="upper right", fontsize="small", framealpha=0.8)
    top_hz = float(np.nanmax(freqs)) if keep.any() else analysis.rate / 2
    ax.set(xlim=(0.0, centres[-1] + unit_s / 2 if len(centres) else 1.0),
           ylim=(0.0, min(analysis.rate / 2, top_hz * 1.08)),
           xlabel="time (s)", ylabel="frequency (Hz)",
           title=f"principal frequencies: top {analysis.top} per {analysis.unit_ms:g} ms unit")
    if colorbar:
        side_colorbar(ax, points, "peak power (dB re strongest)")
    return ax
