"""An actuator's response |H(f)| and the capped equalising weighting 1/|H(f)| (Figure 2c–d):
from a model or a measured CSV (:func:`plot_actuator`), or as measured by the pen itself, with
its coherence, distortion and fitted resonance (:func:`plot_measured_actuator`), and how flat
an equalised multisine arrives (:func:`plot_flatness`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes

from realpen.checks import require_number
from realpen.display.axes import axes_list, check_views, hz_ticks
from realpen.errors import ParameterError

__all__ = ["plot_actuator", "plot_measured_actuator", "plot_flatness", "VIEWS", "MEASURED_VIEWS"]

VIEWS = ("response", "weighting")
MEASURED_VIEWS = ("response", "coherence", "distortion", "weighting")
COHERENT = 0.9  # γ² below this is shaded in the response panel: noise has a say there


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


def plot_measured_actuator(response, ax: Axes | Sequence[Axes] | None = None, *, fit=None,
                           views: str | Sequence[str] = MEASURED_VIEWS,
                           band: tuple[float, float] = (30.0, 500.0), cap_db: float = 20.0
                           ) -> list[Axes]:
    """The method's Figure 2c from a measurement by the pen itself.

    Panels: the measured |H(f)| normalised to 0 dB at its peak, with the fitted resonance
    dashed and the frequencies where the coherence γ² is below 0.9 shaded; the coherence γ²;
    the 2nd + 3rd harmonic distortion (dB re the linear response) with its noise floor; and
    the equalising weighting the tactile pipeline would apply with this response — 1/|H|
    normalised to 0 dB at the best-responding frequency of ``band``, capped at ``cap_db`` (the
    uncapped 1/|H| dashed, the cap dotted).

    Args:
        response: a :class:`realpen.tactile.measure.Response`
            (:func:`realpen.tactile.measure.analyse_sweep`).
        fit: its :class:`realpen.tactile.measure.ResonanceFit` (default: fitted here with
            :func:`realpen.tactile.measure.fit_resonance`).
        band: (low, high) frequency band in Hz of a pattern's components, for the weighting.
        cap_db: cap of the weighting in dB.
        ax: one Axes per view (a single Axes for a single view); None makes a new figure (not
            a pyplot one).
        views: which panels, in order: ``"response"``, ``"coherence"``, ``"distortion"``,
            ``"weighting"``.

    Returns:
        The Axes drawn into, one per view.
    """
    from realpen.tactile.actuator import weighting
    from realpen.tactile.measure import fit_resonance

    low, high = (float(v) for v in band)
    require_number("cap_db", cap_db, minimum=0.0)
    if not (np.isfinite(low) and np.isfinite(high) and 0 < low < high):
        raise ParameterError("band", f"must be (low, high) with 0 < low < high, got {band!r}")
    views = check_views(views, MEASURED_VIEWS)
    drawn = dict(zip(views, axes_list(ax, len(views), (7, 2.4 * len(views)), "ax")))
    freqs = response.frequency_hz
    if fit is None:
        fit = fit_resonance(freqs, response.magnitude, weights=response.coherence)
    peak = float(np.max(response.magnitude))
    measured_db = 20 * np.log10(np.maximum(response.magnitude / peak, 1e-12))

    if "response" in drawn:
        axis = drawn["response"]
        axis.semilogx(freqs, measured_db, color="#1f4e79", lw=1.5,
                      label=f"measured ({response.periods} sweeps)")
        axis.semilogx(freqs, 20 * np.log10(np.maximum(fit.response(freqs) / peak, 1e-12)),
                      color="#b5402a", lw=1, ls="--",
                      label=f"fit: f0 {fit.f0_hz:.1f} Hz, Q {fit.q:.2g} "
                            f"(±{fit.residual_db:.1f} dB)")
        noisy = response.coherence < COHERENT
        if np.any(noisy):
            axis.fill_between(freqs, 0, 1, where=noisy, transform=axis.get_xaxis_transform(),
                              color="#999", alpha=0.25, lw=0, label=f"γ² < {COHERENT:g}")
        axis.set(ylabel="|H(f)| (dB re peak)", ylim=(max(measured_db.min(), -60) - 3, 6),
                 title=f"measured actuator response (SNR {response.snr_db:.0f} dB)")
        axis.legend(loc="lower center", fontsize="small", framealpha=0.9)
    if "coherence" in drawn:
        axis = drawn["coherence"]
        axis.semilogx(freqs, response.coherence, color="#2a7b4f", lw=1.2)
        axis.axhline(COHERENT, color="#999", lw=0.8, ls=":")
        axis.set(ylabel="coherence γ²", ylim=(min(0.8, float(response.coherence.min())) - 0.02,
                                              1.01),
                 title="coherence between the repeated sweeps")
    if "distortion" in drawn:
        axis = drawn["distortion"]
        axis.semilogx(freqs, response.distortion_floor_db, color="#999", lw=1, ls=":",
                      label="noise floor")
        axis.semilogx(freqs, response.distortion_db, color="#7a3b8f", lw=1.5,
                      label="2nd + 3rd harmonics")
        shown = np.concatenate([response.distortion_db, response.distortion_floor_db])
        shown = shown[np.isfinite(shown)]
        top = float(shown.max()) + 6 if shown.size else 0.0
        axis.set(ylabel="distortion (dB re linear)", ylim=(max(top - 60, -100), top),
                 title="harmonic distortion (blank: not measurable or under the floor)")
        axis.legend(loc="upper right", fontsize="small", framealpha=0.9)
    if "weighting" in drawn:
        axis = drawn["weighting"]
        actuator = response.to_actuator()
        weights = weighting(actuator, freqs, (low, high), cap_db)
        uncapped = 20 * np.log10(weights.reference / actuator.response(freqs))
        axis.semilogx(freqs, uncapped, color="#999", lw=1, ls="--", label="1/|H| (uncapped)")
        axis.semilogx(freqs, 20 * np.log10(weights.weights), color="#b5402a", lw=1.5,
                      label=f"weight, capped at {cap_db:g} dB")
        axis.axhline(cap_db, color="#b5402a", lw=0.8, ls=":")
        axis.axvspan(low, high, color="#f2c14e", alpha=0.2, lw=0,
                     label=f"band {low:g}–{high:g} Hz")
        axis.set(ylabel="weight (dB)", ylim=(-3, cap_db + 12),
                 title="equalising weighting w(f) = H_ref / |H(f)|")
        axis.legend(loc="lower left", fontsize="small", framealpha=0.9)
    for axis in drawn.values():
        axis.set_xlabel("frequency (Hz)")
        axis.set_xlim(freqs[0], freqs[-1])
        hz_ticks(axis, freqs[0], freqs[-1])
        axis.grid(True, which="both", alpha=0.3)
    return list(drawn.values())


def plot_flatness(flatness, ax: Axes | None = None, *, tolerance_db: float = 3.0) -> Axes:
    """How flat an equalised multisine arrived: each component's level about the mean (dB),
    the ± ``tolerance_db`` band shaded, components the weighting's cap limited drawn hollow.

    Args:
        flatness: a :class:`realpen.tactile.multisine.Flatness`
            (:func:`realpen.tactile.multisine.flatness`).
        ax: the Axes to draw into; None makes a new figure (not a pyplot one).
        tolerance_db: half-width of the shaded band, dB.

    Returns:
        The Axes drawn into.
    """
    require_number("tolerance_db", tolerance_db, minimum=0.0)
    (axis,) = axes_list(ax, 1, (7, 3), "ax")
    freqs, levels = flatness.frequency_hz, flatness.level_db
    capped = np.asarray(flatness.clipped, dtype=bool)
    axis.axhspan(-tolerance_db, tolerance_db, color="#2a7b4f", alpha=0.12, lw=0,
                 label=f"±{tolerance_db:g} dB")
    axis.axhline(0.0, color="#999", lw=0.8)
    axis.vlines(freqs, 0.0, levels, color="#1f4e79", lw=1)
    axis.semilogx(freqs[~capped], levels[~capped], "o", color="#1f4e79", ms=4,
                  label="component")
    if capped.any():
        axis.semilogx(freqs[capped], levels[capped], "o", mfc="none", color="#b5402a", ms=5,
                      label="weight capped")
    reach = max(float(np.max(np.abs(levels))), tolerance_db) + 2
    low, high = float(freqs.min()) / 1.1, float(freqs.max()) * 1.1
    axis.set(xlabel="frequency (Hz)", ylabel="level (dB re mean)", ylim=(-reach, reach),
             xlim=(low, high),
             title=f"equalised multisine as it arrived: ±{flatness.deviation_db:.1f} dB "
                   f"(spread {flatness.spread_db:.1f} dB, {flatness.periods} loops)")
    hz_ticks(axis, low, high)
    axis.grid(True, which="both", alpha=0.3)
    axis.legend(loc="lower left", fontsize="small", framealpha=0.9)
    return axis
