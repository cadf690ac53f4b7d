"""From a recording to a :class:`~realpen.tactile.pattern.TactilePattern`: the method's pipeline.

1. Preprocess (:func:`realpen.dsp.filters.prepare`): axes → one (DFT321), optional polyphase
   resampling, zero-phase high-pass.
2. Analyse unit sequences of ``selection_unit_ms`` (100 ms) and select the stretch: K × units
   consecutive units, never the first or the last (:func:`realpen.dsp.spectrum.analyze`).
   A recording given as a file is streamed instead: analysed a block at a time, then only the
   stretch (and a margin) read and prepared, so memory stays flat however long it is
   (:mod:`realpen.tactile.stretch`).
3. Principal frequencies per sub-pattern: each selected unit's own (A–C), or — when a
   sub-pattern spans several units (D–F: the 15 units of B's stretch) — those of the
   concatenated units analysed as one unit.
4. Link components across sub-patterns into tracks with continuous phase (crossfade) or draw
   independent phases (hard), seeded.
5. Amplitude ∝ √(power share) (or the share) × the actuator weighting 1/|H(f)| (capped).
6. With ``model="sines+residual"``: each sub-pattern's residual — the power spectral density of
   the same samples its peaks came from, the peaks' main lobes taken out, in bands
   (:mod:`realpen.tactile.residual`) — on the sines' scale, weighted like them.
7. Synthesise (:mod:`realpen.tactile.synthesis`; the residual's noise added) and normalise the
   peak to ``headroom_db`` below full scale.

Per sub-pattern one sinusoid is superposed per principal frequency, with a seeded random phase,
which keeps the crest factor low. A frequency that persists into the next sub-pattern keeps its
phase there (see :mod:`realpen.dsp.tracks`), so crossfades never make it dip. The power ratio is
the component's share of its own sub-pattern's total, so every sub-pattern carries the same
total level and the fluctuation lies in its frequency content.

The residual's scale. With amplitudes ∝ √(power share) the sines are the recording's
sinusoids times one factor per sub-pattern, ``c = 1 / √(2 Σp)`` (a peak of power p has
amplitude √(2p); its component gets √(p / Σp)). The residual takes the same factor: its output
power spectral density is ``c² · R(f) · w(f)²`` (R the residual's density in the recording, w
the capped weighting at the band's centre), so sines and noise keep the recording's balance
before the actuator equalisation. With amplitudes ∝ the power share the sines are no longer a
scaled copy of anything; the residual then takes the factor that keeps the recording's ratio of
residual power to the sines' total power, ``c² = Σ(a²/2) / Σp`` over the unweighted amplitudes
a — which is the same ``c`` in the √ case, so one rule serves both. Sines and residual are
normalised together; the stored levels are after that gain.
"""

from __future__ import annotations

import os

import numpy as np

from realpen.checks import MAX_BANDS, MAX_LEVELS
from realpen.dsp.spectrum import ProgressCallback, principal_frequencies
from realpen.dsp.tracks import continuous_phases, joins, link_components
from realpen.errors import ParameterError, RealPenError, fail
from realpen.io.blocks import RecordingStream
from realpen.io.recording import Recording
from realpen.tactile.actuator import Actuator, as_actuator, weighting
from realpen.tactile.conditions import TactileParams
from realpen.tactile.pattern import Component, TactilePattern
from realpen.tactile.residual import Residual, render_residual, residual_bands, residual_envelope
from realpen.tactile.stretch import Stretch, locate
from realpen.tactile.synthesis import synthesize

__all__ = ["build_pattern", "tactile_pattern", "DEFAULT_ACTUATOR"]

DEFAULT_ACTUATOR = "lra:f0=175,q=8"


def _subpattern_peaks(stretch: Stretch, params: TactileParams
                      ) -> list[tuple[np.ndarray, np.ndarray]]:
    """(frequencies Hz, powers) per sub-pattern, strongest first."""
    per, analysis, source = params.units_per_subpattern, stretch.analysis, stretch.source
    if per == 1:
        peaks = [stretch.peaks(int(unit)) for unit in analysis.selected]
        for unit, (freqs, _) in zip(analysis.selected, peaks):
            if not len(freqs):
                raise fail(source, f"no spectral peaks in selected unit {int(unit)} (at "
                                   f"{float(analysis.starts_s[unit]):.2f} s); it is silent "
                                   f"in the analysed band")
        return peaks
    peaks = []
    for segment in _subpattern_samples(stretch, params):
        # The concatenated units are one unit: exactly their samples.
        _, freqs, powers, _ = principal_frequencies(
            segment, stretch.rate, len(segment) * 1000.0 / stretch.rate, params.top,
            params.highpass_hz, params.fmax_hz, source=source)
        keep = np.isfinite(freqs[0])
        if not keep.any():
            raise fail(source, f"no spectral peaks in the selected "
                               f"{len(segment) / stretch.rate:.2f} s")
        peaks.append((freqs[0][keep], powers[0][keep]))
    return peaks


def _subpattern_samples(stretch: Stretch, params: TactileParams) -> list[np.ndarray]:
    """The samples each sub-pattern's peaks came from: its selected unit, or (D–F) the
    concatenation of its consecutive selected units."""
    per, selected = params.units_per_subpattern, stretch.analysis.selected
    return [stretch.samples(int(selected[index * per]), int(selected[(index + 1) * per - 1]))
            for index in range(params.subpatterns)]


def _residual(stretch: Stretch, params: TactileParams, units, actuator: Actuator,
              band: tuple[float, float]) -> tuple[Residual, int]:
    """The residual before the normalisation gain (levels in full scale per √Hz on the sines'
    relative scale; see the module docstring), and how many bands the weighting cap limited."""
    # Only what the pattern's own rate can hold; the bands fit the levels' limit.
    top = min(band[1], params.rate / 2)
    if top <= (band[0] if band[0] > 0 else 1000.0 / params.unit_ms):
        raise ParameterError("fmax_hz", f"leaves no band for the residual above "
                                        f"{band[0]:g} Hz")
    edges = residual_bands(band[0], top, 1000.0 / params.unit_ms,
                           max_bands=min(MAX_BANDS, MAX_LEVELS // params.subpatterns))
    centres = np.sqrt(np.asarray(edges[:-1]) * np.asarray(edges[1:]))
    weights = weighting(actuator, centres, band, params.cap_db)
    levels = []
    for samples, (freqs, powers) in zip(_subpattern_samples(stretch, params), units):
        density = residual_envelope(samples, stretch.rate, freqs, edges)
        share = powers / powers.sum()
        base = np.sqrt(share) if params.amplitude == "sqrt" else share
        scale_sq = float(np.sum(base ** 2) / 2) / float(powers.sum())
        levels.append(np.sqrt(density * scale_sq) * weights.weights)
    return Residual(edges, levels, params.seed), int(np.sum(weights.clipped))


def build_pattern(recording: Recording | RecordingStream | str | os.PathLike,
                  actuator: Actuator | str = DEFAULT_ACTUATOR, params: TactileParams | None = None,
                  progress: ProgressCallback | None = None, **options) -> TactilePattern:
    """Run the tactile pipeline on a recording (see the module docstring).

    Args:
        recording: a :class:`~realpen.io.recording.Recording` (any axes, any rate) or an array
            with ``input_rate=`` (Hz), analysed in memory; or a path (WAV/FLAC/OGG, CSV, NPZ;
            ``input_rate=`` for a CSV with no time column) or a
            :class:`~realpen.io.blocks.RecordingStream`, streamed, in memory that does not grow
            with the recording (:mod:`realpen.tactile.stretch`).
        actuator: an :class:`~realpen.tactile.actuator.Actuator` or a spec string
            (``"lra:f0=175,q=8"``).
        params: the parameters (default: condition B); ``options`` override its fields
            (:meth:`TactileParams.updated`), or make it when it is None (``condition="E"``,
            ``rate=8000``, …).
        progress: called as ``progress(units_done, units_total)`` during the analysis.

    Returns:
        The pattern, with its actuator, parameters, analysis and provenance.

    Raises:
        ParameterError: a bad parameter, named as in :class:`TactileParams` (e.g. ``rate`` too
            low for the components).
        RealPenError: a problem with the recording (too short, silent, …), naming it.

    Example:
        >>> from realpen.examples import example_recording_path
        >>> build_pattern(example_recording_path(), "lra:f0=175,q=8", condition="E")
        TactilePattern(1 sub-pattern × 1500 ms, 10 components each, 8000 Hz, lra:f0=175,q=8)
    """
    input_rate = options.pop("input_rate", None)
    if params is None:
        params = TactileParams(**options)
    elif not isinstance(params, TactileParams):
        raise ParameterError("params", f"must be TactileParams, got {type(params).__name__}")
    elif options:
        params = params.updated(**options)
    actuator = as_actuator(actuator)
    stretch = locate(recording, params, input_rate=input_rate, progress=progress)
    analysis = stretch.analysis
    units = _subpattern_peaks(stretch, params)
    highest = max(float(np.max(freqs)) for freqs, _ in units)
    if highest >= params.rate / 2:
        raise ParameterError("rate", f"{params.rate} Hz is too low for components up to "
                                     f"{highest:.0f} Hz")
    band = (params.highpass_hz, params.fmax_hz or stretch.rate / 2)
    rng = np.random.default_rng(params.seed)
    freqs_per_sub = [freqs for freqs, _ in units]
    if params.boundary == "crossfade":
        # Half the peak separation: two links can never claim the same peak.
        tolerance = 0.5 * 1000.0 / params.unit_ms
        successors = link_components(freqs_per_sub, tolerance, cyclic=True)
        phases_per_sub, freqs_per_sub = continuous_phases(freqs_per_sub, successors,
                                                          params.unit_ms / 1000.0, rng)
        joins_previous, joins_next = joins(successors)
    else:  # the literal method: independent sub-patterns, independent random phases
        phases_per_sub = [rng.uniform(0.0, 2 * np.pi, size=len(f)) for f in freqs_per_sub]
        joins_previous = joins_next = [np.zeros(len(f), dtype=bool) for f in freqs_per_sub]
    relative = []
    for index, (_, powers) in enumerate(units):
        freqs = freqs_per_sub[index]
        share = powers / powers.sum()
        weights = weighting(actuator, freqs, band, params.cap_db)
        base = np.sqrt(share) if params.amplitude == "sqrt" else share
        relative.append((freqs, powers, weights.weights, base * weights.weights,
                         phases_per_sub[index], weights.clipped, joins_previous[index],
                         joins_next[index]))
    raw = synthesize([(f, a, p, jp, jn) for f, _, _, a, p, _, jp, jn in relative], params.rate,
                     params.unit_ms, params.boundary, params.crossfade_ms)
    residual, residual_clipped = None, 0
    if params.model == "sines+residual":
        residual, residual_clipped = _residual(stretch, params, units, actuator, band)
        raw = raw + render_residual(residual, params.rate, params.unit_ms, params.crossfade_ms)
    peak = float(np.max(np.abs(raw)))
    if not np.isfinite(peak) or peak <= 0:
        raise RealPenError(f"{stretch.source}: the pattern came out silent or not finite; "
                           f"check the actuator and weighting parameters")
    gain = 10 ** (-params.headroom_db / 20) / peak
    subpatterns = [[Component(float(f), float(a * gain), float(p), float(pw), float(w), bool(c),
                              bool(jp), bool(jn))
                    for f, pw, w, a, p, c, jp, jn in zip(*sub)] for sub in relative]
    first, last = int(analysis.selected[0]), int(analysis.selected[-1])
    provenance = {**stretch.provenance, "gain": gain,
                  "stretch_s": (float(analysis.starts_s[first]),
                                float(analysis.starts_s[last]
                                      + stretch.unit_samples / stretch.rate))}
    clipped = sum(bool(c) for sub in relative for c in sub[5])
    notes = ((f"{clipped} component(s) limited by the {params.cap_db:g} dB weighting cap",)
             if clipped else ())
    if residual is not None:
        residual = residual.scaled(gain)
        sines = sum(c.amplitude ** 2 / 2 for sub in subpatterns for c in sub)
        noise = float(np.sum(residual.powers))
        notes += (f"residual: {residual.bands} bands, {residual.band_edges_hz[0]:g}–"
                  f"{residual.band_edges_hz[-1]:.0f} Hz, {100 * noise / (noise + sines):.0f} % "
                  f"of the pattern's power",)
        if residual_clipped:
            notes += (f"{residual_clipped} residual band(s) limited by the {params.cap_db:g} dB "
                      f"weighting cap",)
    pattern = TactilePattern(subpatterns, params.rate, params.unit_ms, params.boundary,
                             params.crossfade_ms, actuator, params, analysis, provenance, notes,
                             residual=residual)
    return pattern.with_samples(raw * gain)


def tactile_pattern(recording, actuator: Actuator | str = DEFAULT_ACTUATOR, *,
                    condition: str | None = None, progress: ProgressCallback | None = None,
                    **options) -> TactilePattern:
    """The tactile pattern of a recording for an actuator, as the method makes it.

    Args:
        recording: a :class:`~realpen.io.recording.Recording` or an array with
            ``input_rate=`` (Hz), analysed whole; or a path or a
            :class:`~realpen.io.blocks.RecordingStream`, streamed (see :func:`build_pattern`).
        actuator: an :class:`~realpen.tactile.actuator.Actuator` or a spec string.
        condition: a study condition A–F (None: B's counts, or the counts given).
        progress: called as ``progress(units_done, units_total)``.
        options: any field of :class:`~realpen.tactile.conditions.TactileParams` (``top``,
            ``subpatterns``, ``unit_ms``, ``rate`` in Hz, ``boundary``, ``seed``, ``cap_db``, …).

    Example:
        >>> from realpen.examples import example_recording_path
        >>> pattern = tactile_pattern(example_recording_path(), condition="B")
        >>> len(pattern.subpatterns), pattern.duration_s
        (15, 1.5)
    """
    return build_pattern(recording, actuator, None, progress, condition=condition, **options)
