"""An actuator's response |H(f)| and the capped equalising weighting 1/|H(f)| (Figure 2c–d)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes

from realpen.display._axes import axes_list, hz_ticks
from realpen.errors import ParameterError, require_number

__all__ = ["plot_actuator"]


def plot_actuator(actuator, *, band: tuple[float, float] = (30.0, 500.0), cap_db: float = 20.0,
                  axes: Sequence[Axes] | None = None) -> list[Axes]:
    """Two panels: the actuator's response |H(f)| and the weighting that equalises it.

    The weighting is the one the tactile pipeline applies: 1/|H(f)| normalised to 1 (0 dB) at
    the best-responding frequency of ``band`` and capped at ``cap_db``; the uncapped 1/|H| is
    drawn dashed, the band shaded, the cap as a dotted line.

    Args:
        actuator: an :class:`realpen.Actuator` or a spec string (``"lra:f0=175,q=8"``).
        band: (low, high) frequency band in Hz of the pattern's components.
        cap_db: cap of the weighting in dB.
        axes: two Axes (response, weighting); None makes a new figure (not a pyplot one).

    Returns:
        The two Axes, [response, weighting].

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
    response_ax, weight_ax = axes_list(axes, 2, (7, 5.5))
    freqs = np.geomspace(low / 2, high * 2, 800)
    response_db = 20 * np.log10(np.maximum(actuator.response(freqs), 1e-12))
    weights = weighting(actuator, freqs, (low, high), cap_db)
    reference_db = 20 * np.log10(weights.reference)
    spec = getattr(actuator, "spec", str(actuator))

    response_ax.semilogx(freqs, response_db, color="#1f4e79", lw=1.5)
    response_ax.set(ylabel="|H(f)| (dB)", title=f"actuator response: {spec}",
                    ylim=(max(response_db.min(), reference_db - cap_db - 30) - 3,
                          response_db.max() + 3))
    weight_ax.semilogx(freqs, reference_db - response_db, color="#999", lw=1, ls="--",
                       label="1/|H| (uncapped)")
    weight_ax.semilogx(freqs, 20 * np.log10(weights.weights), color="#b5402a", lw=1.5,
                       label=f"weight, capped at {cap_db:g} dB")
    weight_ax.axhline(cap_db, color="#b5402a", lw=0.8, ls=":")
    weight_ax.set(xlabel="frequency (Hz)", ylabel="weight (dB)", ylim=(-3, cap_db + 12),
                  title="equalising weighting w(f) = H_ref / |H(f)|")
    response_ax.set_xlabel("frequency (Hz)")
    for ax in (weight_ax, response_ax):
        ax.axvspan(low, high, color="#f2c14e", alpha=0.2, lw=0,
                   label=f"band {low:g}–{high:g} Hz" if ax is weight_ax else None)
        ax.set_xlim(freqs[0], freqs[-1])
        hz_ticks(ax, freqs[0], freqs[-1])
        ax.grid(True, which="both", alpha=0.3)
    weight_ax.legend(loc="upper center", fontsize="small", framealpha=0.9)
    return [response_ax, weight_ax]
