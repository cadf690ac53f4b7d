"""An actuator's response |H(f)| and the capped equalising weighting 1/|H(f)| (Figure 2c–d)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes

from realpen.checks import require_number
from realpen.display.axes import axes_list, check_views, hz_ticks
from realpen.errors import ParameterError

__all__ = ["plot_actuator", "VIEWS"]

VIEWS = ("response", "weighting")


def plot_actuator(actuator, ax: Axes | Sequence[Axes] | None = None, *,
                  views: str | Sequence[str] = VIEWS, band: tuple[float, float] = (30.0, 500.0),
                  cap_db: float = 20.0) -> list[Axes]:
    """Two panels: the actuator's response |H(f)| and the weighting that equalises it.

    The weighting is the one the tactile pipeline applies: 1/|H(f)| normalised to 1 (0 dB) at
    the best-responding frequency of ``band`` and capped at ``cap_db``; the uncapped 1/|H| is
    drawn dashed, the band shaded, the cap as a dotted line.

    Args:
        actuator: an :class:`realpen.Actuator` or a spec string (``"lra:f0=175,q=8"``).
        band: (low, high) frequency band in Hz of the pattern's components.
        cap_db: cap of the weighting in dB.
        ax: one Axes per view (a single Axes for a single view); None makes a new figure (not
            a pyplot one).
        views: which panels, in order: ``"response"`` and/or ``"weighting"``.

    Returns:
        The Axes drawn into, one per view.

    Example:
        >>> import realpen as rp
        >>> response, weighting = rp.display.plot_actuator("lra:f0=175,q=8")
        >>> weighting.get_ylabel()
        'weight (dB)'
    """
    from realpen.tactile.actuator import parse_actuator, weighting

    low, high = (float(v) for v in band)
    require_number("cap_db", cap_db, minimum=0.0)
    if not (np.isfinite(low) and np.isfinite(high) and 0 < low < high):
        raise ParameterError("band", f"must be (low, high) with 0 < low < high, got {band!r}")
    if isinstance(actuator, str):
        actuator = parse_actuator(actuator)
    views = check_views(views, VIEWS)
    drawn = dict(zip(views, axes_list(ax, len(views), (7, 2.75 * len(views)), "ax")))
    freqs = np.geomspace(low / 2, high * 2, 800)
    response_db = 20 * np.log10(np.maximum(actuator.response(freqs), 1e-12))
    weights = weighting(actuator, freqs, (low, high), cap_db)
    reference_db = 20 * np.log10(weights.reference)
    spec = getattr(actuator, "spec", str(actuator))

    if "response" in drawn:
        response_ax = drawn["response"]
        response_ax.semilogx(freqs, response_db, color="#1f4e79", lw=1.5)
        response_ax.set(ylabel="|H(f)| (dB)", title=f"actuator response: {spec}",
                        ylim=(max(response_db.min(), reference_db - cap_db - 30) - 3,
                              response_db.max() + 3))
    if "weighting" in drawn:
        weight_ax = drawn["weighting"]
        weight_ax.semilogx(freqs, reference_db - response_db, color="#999", lw=1, ls="--",
                           label="1/|H| (uncapped)")
        weight_ax.semilogx(freqs, 20 * np.log10(weights.weights), color="#b5402a", lw=1.5,
                           label=f"weight, capped at {cap_db:g} dB")
        weight_ax.axhline(cap_db, color="#b5402a", lw=0.8, ls=":")
        weight_ax.set(ylabel="weight (dB)", ylim=(-3, cap_db + 12),
                      title="equalising weighting w(f) = H_ref / |H(f)|")
    for view, axis in drawn.items():
        axis.set_xlabel("frequency (Hz)")
        axis.axvspan(low, high, color="#f2c14e", alpha=0.2, lw=0,
                     label=f"band {low:g}–{high:g} Hz" if view == "weighting" else None)
        axis.set_xlim(freqs[0], freqs[-1])
        hz_ticks(axis, freqs[0], freqs[-1])
        axis.grid(True, which="both", alpha=0.3)
    if "weighting" in drawn:
        drawn["weighting"].legend(loc="upper center", fontsize="small", framealpha=0.9)
    return list(drawn.values())
