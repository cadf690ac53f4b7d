"""The stochastic residual of a tactile pattern: what the sinusoids leave out, as shaped noise.

Spectral modelling synthesis (Serra & Smith 1990, "Spectral modeling synthesis: a sound
analysis/synthesis system based on a deterministic plus stochastic decomposition", Computer
Music Journal 14(4), doi:10.2307/3680788) renders a signal as its principal sinusoids *plus* a
residual: the spectral envelope of what remains once the sinusoids are taken out, played as
noise with that envelope. The method's patterns keep only the sinusoids; a stylus on paper is
mostly broadband, so most of its power lies in the floor between the peaks.

Analysis (:func:`residual_envelope`). The unit's power spectral density is computed with the
conventions of :func:`realpen.dsp.spectrum.principal_frequencies` (mean removed, periodic Hann
window of the unit's length, FFT zero-padded to :func:`~realpen.dsp.spectrum.fft_size`), scaled
as a one-sided density, ``PSD = 2·|X|² / (rate·Σw²)`` in (recording unit)²/Hz, so that

- a sinusoid of amplitude ``A`` (peak power ``A²/2`` in the analysis) integrates to ``A²/2``,
- the integral of the PSD over a band is the band's mean-square power,

and the sines and the residual are on one scale. Each chosen peak's main lobe (±
:data:`LOBE_BINS` bins of the *unpadded* window, the Hann main lobe's half-width) is taken out
and the gap bridged by straight-line interpolation of the log-PSD between the mean levels just
outside it. The result is averaged (linearly: mean power density) into bands.

Bands (:func:`residual_bands`). Twelfth-octave bands (6 % wide), never narrower than the
analysed unit's frequency resolution (1000 / unit_ms Hz: 10 Hz for 100 ms units), from the
high-pass (30 Hz) to the top of the peak band (the analysis Nyquist, 672 Hz at 1344 Hz). Bands
narrower than the unit's resolution would hold nothing the unit's spectrum has; a twelfth of an
octave is well below vibrotactile frequency discrimination (Weber fractions of 20–30 % in the
Pacinian range; Goff 1967, doi:10.1037/h0024134), so the steps between bands are not felt. The
levels are equalised for the actuator at each band's centre, so bands must also be narrow
where the actuator's response is steep: an LRA of Q 8 at 175 Hz spans 3 dB in about 22 Hz.
Sixth-octave bands (20 Hz there) tilted each band by several dB through the actuator; on the
HaTT paper textures (``benchmarks/bench_fidelity.py``'s setting) twelfth-octave bands brought
the weighted log-spectral distance from 1.55 to 1.43 times the noise-loop floor (median of 24
points), and finer ones nothing more. For 100 ms units at 1344 Hz that is 38 bands (10 Hz wide
up to 170 Hz); for the D–F stretch of 1500 ms, 54.

Rendering (:func:`render_residual`). Per sub-pattern, a noise with the band's amplitude spectral
density: random phases from ``seed`` (one stream per sub-pattern), magnitudes from the bands'
power integrated over each FFT bin (energy-preserving however the bins and bands fall), built
with ``irfft`` over the segment (over twice its length for a loop of one sub-pattern, whose
segment's head and tail overlap at the wrap: with a period of one segment they would be the same
noise ``crossfade_ms`` apart, correlated at low frequencies). Segments
are ``crossfade_ms`` longer than a sub-pattern, faded in and out with equal-power (sin/cos)
ramps — neighbours are uncorrelated noise, so their powers add to a constant — and overlap-added
at positions modulo the loop's length exactly as :func:`realpen.tactile.synthesis.synthesize`
does, so the loop's wrap is an ordinary crossfade. Noise never joins hard: with
``boundary="hard"`` (or a crossfade below :data:`MIN_FADE_MS`) the residual still crossfades over
:data:`MIN_FADE_MS`; an abrupt change of a noise's spectrum clicks.

The noise is deterministic from the JSON (seed, edges, levels) at a given rate; at another rate
it is another realisation of the same spectrum (the FFT lengths differ), and bands above that
rate's Nyquist frequency are left out.

numpy only (the analysis loads :mod:`realpen.dsp.spectrum` when called): the pattern type, and
through it the profile schema, imports this module.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from realpen.checks import (
    MAX_BANDS,
    MAX_LEVELS,
    MAX_RATE_HZ,
    MAX_SEED,
    MAX_SUBPATTERNS,
    check_frames,
    check_number_list,
    require_number,
)
from realpen.errors import ParameterError
from realpen.tactile.synthesis import fade_samples, subpattern_samples

__all__ = ["Residual", "residual_envelope", "residual_bands", "render_residual",
           "residual_fade_samples", "band_psd_at", "LOBE_BINS", "BANDS_PER_OCTAVE",
           "MIN_FADE_MS"]

LOBE_BINS = 2.0
"""Half-width (bins of the unpadded Hann window, ``rate / N`` Hz) of the main lobe taken out
around each chosen peak."""
BANDS_PER_OCTAVE = 12
MIN_FADE_MS = 5.0
"""The shortest crossfade of the residual between sub-patterns and at the wrap (ms), whatever
the pattern's boundary: the sines' default crossfade."""
_TINY = 1e-300


def _numbers(name: str, value: Any, maximum: int) -> np.ndarray:
    """``value`` as a float64 array: a list of at most ``maximum`` finite numbers."""
    array = np.asarray(check_number_list(name, value, maximum), dtype=np.float64)
    if not np.all(np.isfinite(array)):
        raise ParameterError(name, "must hold finite numbers only")
    return array


@dataclass(frozen=True, repr=False)
class Residual:
    """The residual of a pattern: a noise level per band and sub-pattern, and the noise's seed.

    Attributes:
        band_edges_hz: the B + 1 band edges in Hz, strictly ascending, > 0 (at most
            :data:`~realpen.checks.MAX_BANDS` bands, the top edge at most half of
            :data:`realpen.checks.MAX_RATE_HZ`).
        levels: per sub-pattern, B amplitude spectral densities of the residual in the *output*
            pattern, full scale per √Hz (≥ 0; already equalised for the actuator and scaled by
            the pattern's normalisation gain). A band's power is ``level² × width``.
        seed: seed of the noise's random phases (0 … :data:`realpen.checks.MAX_SEED`).

    Raises:
        ParameterError: a bad value, named by its field (lists, tuples and arrays are accepted
            and stored as tuples of floats).

    Example:
        >>> Residual((30.0, 100.0, 500.0), ((1e-3, 5e-4),), seed=0)
        Residual(1 sub-pattern × 2 bands, 30–500 Hz, seed 0)
    """

    band_edges_hz: tuple[float, ...]
    levels: tuple[tuple[float, ...], ...]
    seed: int = 0

    def __post_init__(self) -> None:
        edges = _numbers("band_edges_hz", self.band_edges_hz, MAX_BANDS + 1)
        if len(edges) < 2:
            raise ParameterError("band_edges_hz", "needs at least two edges (one band)")
        if edges[0] <= 0 or np.any(np.diff(edges) <= 0):
            raise ParameterError("band_edges_hz", "must be positive and strictly ascending")
        if edges[-1] > MAX_RATE_HZ / 2:
            raise ParameterError("band_edges_hz", f"must be <= {MAX_RATE_HZ / 2:g} Hz (half the "
                                                  f"highest rate), got {edges[-1]:g}")
        rows = check_number_list("levels", self.levels)
        if not rows:
            raise ParameterError("levels", "needs the levels of at least one sub-pattern")
        if len(rows) > MAX_SUBPATTERNS:
            raise ParameterError("levels", f"{len(rows):,} sub-patterns; at most "
                                           f"{MAX_SUBPATTERNS}")
        bands = len(edges) - 1
        if len(rows) * bands > MAX_LEVELS:
            raise ParameterError("levels", f"{len(rows)} sub-patterns × {bands} bands are "
                                           f"{len(rows) * bands:,} levels; at most "
                                           f"{MAX_LEVELS:,}")
        levels = []
        for index, row in enumerate(rows):
            values = _numbers("levels", row, bands)
            if len(values) != bands:
                raise ParameterError("levels", f"sub-pattern {index} has {len(values)} levels; "
                                               f"the {len(edges)} band edges make {bands} bands")
            if np.any(values < 0):
                raise ParameterError("levels", "must be >= 0")
            levels.append(tuple(float(v) for v in values))
        if isinstance(self.seed, (bool, np.bool_)) or not isinstance(self.seed,
                                                                     (int, np.integer)):
            raise ParameterError("seed", f"must be a whole number, got {self.seed!r}")
        require_number("seed", int(self.seed), minimum=0, maximum=MAX_SEED)
        object.__setattr__(self, "band_edges_hz", tuple(float(v) for v in edges))
        object.__setattr__(self, "levels", tuple(levels))
        object.__setattr__(self, "seed", int(self.seed))

    def __repr__(self) -> str:
        count = len(self.levels)
        return (f"Residual({count} sub-pattern{'s' if count != 1 else ''} × {self.bands} bands, "
                f"{self.band_edges_hz[0]:g}–{self.band_edges_hz[-1]:g} Hz, seed {self.seed})")

    @property
    def bands(self) -> int:
        """How many bands (B)."""
        return len(self.band_edges_hz) - 1

    @property
    def centres_hz(self) -> np.ndarray:
        """Geometric centre of each band in Hz, shape (B,)."""
        edges = np.asarray(self.band_edges_hz)
        return np.sqrt(edges[:-1] * edges[1:])

    @property
    def powers(self) -> np.ndarray:
        """Mean-square power of the residual in each sub-pattern (full scale²), shape (K,)."""
        widths = np.diff(self.band_edges_hz)
        return (np.asarray(self.levels) ** 2 * widths).sum(axis=1)

    def scaled(self, gain: float) -> Residual:
        """The residual with every level multiplied by ``gain`` (≥ 0)."""
        require_number("gain", gain, minimum=0.0)
        return Residual(self.band_edges_hz, np.asarray(self.levels) * gain, self.seed)

    def to_json(self) -> dict:
        """``{"band_edges_hz": [...], "levels": [[...], ...], "seed": int}`` (the ``residual``
        of a pattern's JSON)."""
        return {"band_edges_hz": list(self.band_edges_hz),
                "levels": [list(row) for row in self.levels], "seed": self.seed}

    @classmethod
    def from_json(cls, data: Any) -> Residual:
        """A residual from :meth:`to_json`'s form.

        Raises:
            ParameterError: (parameter ``residual``) not an object, unknown or missing fields;
                bad values are named by their field.
        """
        if isinstance(data, Residual):
            return data
        if not isinstance(data, dict):
            raise ParameterError("residual", f"must be an object, got {type(data).__name__}")
        names = ("band_edges_hz", "levels", "seed")
        unknown = sorted(set(data) - set(names))
        if unknown:
            raise ParameterError("residual", f"unknown field(s) {', '.join(unknown)}")
        missing = [name for name in names[:2] if name not in data]
        if missing:
            raise ParameterError("residual", f"needs {' and '.join(missing)}")
        return cls(**data)


def residual_bands(low_hz: float, high_hz: float, resolution_hz: float,
                   per_octave: int = BANDS_PER_OCTAVE, max_bands: int = MAX_BANDS
                   ) -> tuple[float, ...]:
    """Band edges in Hz: ``per_octave`` bands per octave, none narrower than ``resolution_hz``.

    Args:
        low_hz: lower edge in Hz (the high-pass; ``resolution_hz`` when it is 0).
        high_hz: upper edge in Hz (the top of the peak band).
        resolution_hz: the analysed unit's frequency resolution, 1000 / unit_ms Hz.
        per_octave: bands per octave where they are wider than the resolution.
        max_bands: the most bands; beyond it, ``max_bands`` log-spaced ones.

    Returns:
        The edges, ascending; a last band narrower than half its neighbour is merged into it.

    Raises:
        ParameterError: (parameter ``high_hz``) no band between the two edges.

    Example:
        >>> len(residual_bands(30.0, 672.0, 10.0)) - 1
        38
    """
    require_number("resolution_hz", resolution_hz, minimum=0.0, inclusive=False)
    low = float(low_hz) if low_hz > 0 else float(resolution_hz)
    require_number("high_hz", high_hz, minimum=low, inclusive=False)
    ratio = 2.0 ** (1.0 / per_octave)
    edges = [low]
    while edges[-1] < high_hz and len(edges) <= max_bands + 1:
        edges.append(min(max(edges[-1] * ratio, edges[-1] + resolution_hz), float(high_hz)))
    if len(edges) > max_bands + 1:
        return tuple(float(v) for v in np.geomspace(low, high_hz, max_bands + 1))
    if len(edges) > 2 and edges[-1] - edges[-2] < 0.5 * (edges[-2] - edges[-3]):
        del edges[-2]
    return tuple(edges)


def residual_envelope(unit_samples: np.ndarray, rate: float, frequencies_hz: np.ndarray,
                      band_edges_hz: tuple[float, ...] | np.ndarray, *,
                      lobe_bins: float = LOBE_BINS) -> np.ndarray:
    """The power spectral density per band of one unit with its chosen peaks taken out.

    Args:
        unit_samples: the unit's samples (one axis, high-passed), in the recording's unit.
        rate: their rate in Hz.
        frequencies_hz: the peaks to take out (the sub-pattern's principal frequencies), Hz.
        band_edges_hz: B + 1 band edges in Hz, ascending.
        lobe_bins: half-width of the lobe taken out around each peak, in bins of the unpadded
            window (``rate / len(unit_samples)`` Hz).

    Returns:
        Mean PSD per band, (recording unit)²/Hz, shape (B,); 0 for a band above ``rate / 2``.
        ``Σ psd × widths`` is the residual's mean-square power in the bands.

    Raises:
        ParameterError: fewer than 8 samples, or a bad ``rate`` or ``lobe_bins``.

    Example:
        >>> rng = np.random.default_rng(0)
        >>> t = np.arange(1344 * 4) / 1344
        >>> x = np.sin(2 * np.pi * 200 * t) + rng.normal(0, 0.1, len(t))  # white: 2σ²/rate
        >>> psd = residual_envelope(x, 1344, [200.0], (150.0, 250.0))
        >>> round(float(psd[0] / (2 * 0.01 / 1344)), 1)
        1.0
    """
    from realpen.dsp.spectrum import fft_size

    x = np.asarray(unit_samples, dtype=np.float64).reshape(-1)
    require_number("rate", rate, minimum=0.0, inclusive=False)
    require_number("lobe_bins", lobe_bins, minimum=0.0)
    if len(x) < 8:
        raise ParameterError("unit_samples", f"needs at least 8 samples, got {len(x)}")
    edges = np.asarray(band_edges_hz, dtype=np.float64)
    count = len(x)
    nfft = fft_size(count)
    # The periodic Hann window, as scipy.signal.get_window("hann", N) in the analysis.
    window = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(count) / count)
    spectrum = np.fft.rfft((x - x.mean()) * window, n=nfft)
    psd = (spectrum.real ** 2 + spectrum.imag ** 2) * (2.0 / (rate * np.sum(window ** 2)))
    freqs = np.fft.rfftfreq(nfft, 1.0 / rate)
    bin_hz = rate / count
    peaks = np.asarray(frequencies_hz, dtype=np.float64).reshape(-1)
    peaks = peaks[np.isfinite(peaks)]
    masked = np.zeros(len(freqs), dtype=bool)
    for f in peaks:
        masked[_span(freqs, f, lobe_bins * bin_hz)] = True
    if masked.any():
        psd = _without_sidelobes(psd, freqs, peaks, count, rate)
        psd = _bridge(psd, freqs, masked, max(1, int(round(nfft / count))))
    # Mean density over the padded bins inside each band; a band between two bins takes the
    # density at its centre.
    out = np.zeros(len(edges) - 1)
    first = np.searchsorted(freqs, edges[:-1], side="left")
    last = np.searchsorted(freqs, edges[1:], side="left")
    for band, (a, b) in enumerate(zip(first, last)):
        if edges[band] >= rate / 2:
            continue
        if b > a:
            out[band] = float(np.mean(psd[a:b]))
        else:
            out[band] = float(np.interp(np.sqrt(edges[band] * edges[band + 1]), freqs, psd))
    return out


def _hann_response(offset_hz: np.ndarray, count: int, rate: float) -> np.ndarray:
    """|W(f)|² / |W(0)|² of the periodic Hann window of ``count`` samples at ``offset_hz``."""
    omega = 2 * np.pi * np.asarray(offset_hz) / rate

    def rectangle(w: np.ndarray) -> np.ndarray:  # Σ e^{-jωn}, n < count; count where ω ≡ 0
        denominator = 1 - np.exp(-1j * w)
        small = np.abs(denominator) < 1e-12
        safe = np.where(small, 1.0, denominator)
        return np.where(small, count, (1 - np.exp(-1j * w * count)) / safe)

    step = 2 * np.pi / count
    response = 0.5 * rectangle(omega) - 0.25 * rectangle(omega - step) \
        - 0.25 * rectangle(omega + step)
    return np.abs(response) ** 2 / (0.5 * count) ** 2


def _without_sidelobes(psd: np.ndarray, freqs: np.ndarray, peaks: np.ndarray, count: int,
                       rate: float, reach_bins: int = 16) -> np.ndarray:
    """The PSD less each peak's leakage through the window's sidelobes (the main lobe is
    bridged afterwards). A strong sinusoid leaks about −28 dB of its power beyond its main lobe
    (the Hann sidelobes), which would otherwise read as residual around it; SMS subtracts the
    modelled sinusoids, and this is that subtraction in the power domain. Within
    ``reach_bins`` unpadded bins (further out the sidelobes are below −80 dB); no bin loses more
    than 99 % of its power (the peak's level is measured, not known)."""
    bin_hz = rate / count
    leak = np.zeros_like(psd)
    for f in peaks:
        near, reach = _span(freqs, f, 0.5 * bin_hz), _span(freqs, f, reach_bins * bin_hz)
        if near.start >= near.stop:
            continue
        leak[reach] += float(np.max(psd[near])) * _hann_response(freqs[reach] - f, count, rate)
    return np.maximum(psd - leak, 0.01 * psd)


def _span(freqs: np.ndarray, centre: float, half_width: float) -> slice:
    """The bins of the evenly spaced ``freqs`` within ``half_width`` of ``centre`` (a slice:
    a unit of 2²⁰ samples has 4 million bins, too many to compare for every peak)."""
    step = freqs[1] - freqs[0]
    first = max(0, int(np.ceil((centre - half_width) / step - 1e-9)))
    last = min(len(freqs) - 1, int(np.floor((centre + half_width) / step + 1e-9)))
    return slice(first, max(first, last + 1))


def _bridge(psd: np.ndarray, freqs: np.ndarray, masked: np.ndarray, span: int) -> np.ndarray:
    """Fill each masked run by straight-line interpolation of the log-PSD between the mean
    levels of up to ``span`` unmasked bins on either side (one unpadded bin: a single padded bin
    of a periodogram is too noisy to anchor on)."""
    psd = psd.copy()
    change = np.flatnonzero(np.diff(np.concatenate([[0], masked.astype(np.int8), [0]])))
    starts, stops = change[::2], change[1::2]  # runs [start, stop)
    if len(starts) == 1 and starts[0] == 0 and stops[0] == len(psd):
        return np.zeros_like(psd)  # nothing outside the peaks
    original = psd.copy()
    for start, stop in zip(starts, stops):
        anchors = []
        for side in (range(start - 1, max(start - 1 - span, -1), -1),
                     range(stop, min(stop + span, len(psd)))):
            picked = [i for i in side if not masked[i]]
            if picked:
                anchors.append((float(np.mean(freqs[picked])),
                                math.log(max(float(np.mean(original[picked])), _TINY))))
        if not anchors:
            psd[start:stop] = 0.0
            continue
        if len(anchors) == 1:
            psd[start:stop] = math.exp(anchors[0][1])
            continue
        (f0, l0), (f1, l1) = anchors
        psd[start:stop] = np.exp(l0 + (l1 - l0) * (freqs[start:stop] - f0) / (f1 - f0))
    return psd


def residual_fade_samples(rate: float, subpattern_ms: float, crossfade_ms: float) -> int:
    """The residual's crossfade in samples: ``max(crossfade_ms, MIN_FADE_MS)``, even, at most
    one sub-pattern, and at least 2 samples where the sub-pattern holds them (noise never joins
    hard)."""
    length = subpattern_samples(rate, subpattern_ms)
    fade = fade_samples(rate, subpattern_ms, "crossfade", max(crossfade_ms, MIN_FADE_MS))
    return max(fade, min(2, length - length % 2))


def band_psd_at(edges_hz: np.ndarray, psd: np.ndarray, centres_hz: np.ndarray,
                width_hz: float) -> np.ndarray:
    """The mean of a band-wise constant PSD over bins of ``width_hz`` around ``centres_hz``
    (the band powers integrated over each bin, so no power is lost or doubled however bins and
    bands fall), in the PSD's unit."""
    edges = np.asarray(edges_hz, dtype=np.float64)
    cumulative = np.concatenate([[0.0], np.cumsum(np.asarray(psd) * np.diff(edges))])
    lo = np.interp(centres_hz - width_hz / 2, edges, cumulative)
    hi = np.interp(centres_hz + width_hz / 2, edges, cumulative)
    return (hi - lo) / width_hz


def render_residual(residual: Residual, rate: float, subpattern_ms: float,
                    crossfade_ms: float = 5.0, subpatterns: int | None = None) -> np.ndarray:
    """One loop of the residual noise at ``rate`` Hz (see the module docstring).

    Args:
        residual: the :class:`Residual` (levels in full scale per √Hz).
        rate: output rate in Hz.
        subpattern_ms: length of each sub-pattern in ms (the pattern's).
        crossfade_ms: the pattern's crossfade in ms; the residual uses at least
            :data:`MIN_FADE_MS`, whatever the boundary.
        subpatterns: the pattern's sub-pattern count, checked against the residual's when given.

    Returns:
        float64, shape (sub-patterns × ``round(subpattern_ms × rate / 1000)``,), looping
        seamlessly; its mean square in each sub-pattern is that sub-pattern's
        :attr:`Residual.powers` (the bands below ``rate / 2``).

    Raises:
        ParameterError: a bad ``rate``, ``subpattern_ms`` or ``crossfade_ms``, a loop longer
            than :data:`~realpen.checks.MAX_PATTERN_FRAMES`, or a ``subpatterns``
            count that is not the residual's.

    Example:
        >>> residual = Residual((30.0, 500.0), ((1e-2,), (2e-2,)), seed=1)
        >>> render_residual(residual, 8000, 100.0).shape
        (1600,)
    """
    if not isinstance(residual, Residual):
        raise ParameterError("residual", f"must be a Residual, got {type(residual).__name__}")
    require_number("rate", rate, minimum=0.0, inclusive=False)
    require_number("subpattern_ms", subpattern_ms, minimum=0.0, inclusive=False)
    require_number("crossfade_ms", crossfade_ms, minimum=0.0)
    count = len(residual.levels)
    if subpatterns is not None and subpatterns != count:
        raise ParameterError("residual", f"has the levels of {count} sub-pattern(s); the "
                                         f"pattern has {subpatterns}")
    length = subpattern_samples(rate, subpattern_ms)
    if length < 1:
        raise ParameterError("subpattern_ms", f"{subpattern_ms:g} ms is less than one sample at "
                                              f"{rate:g} Hz")
    total = check_frames(count, rate, subpattern_ms)
    fade = residual_fade_samples(rate, subpattern_ms, crossfade_ms)
    segment = length + fade
    # The noise's period: one segment, or two when a lone segment overlaps itself at the wrap.
    n = segment if count > 1 else 2 * segment
    freqs = np.fft.rfftfreq(n, 1.0 / rate)
    inside = (freqs > 0) & (freqs < rate / 2)
    edges = np.asarray(residual.band_edges_hz)
    u = (np.arange(fade) + 0.5) / max(fade, 1)
    fade_in = np.sin(0.5 * np.pi * u)
    out = np.zeros(total)
    for index, levels in enumerate(residual.levels):
        density = band_psd_at(edges, np.square(levels), freqs[inside], rate / n)
        if not np.any(density > 0):
            continue
        # |X| so that irfft's mean square is Σ PSD·Δf (one-sided bins, Δf = rate / n).
        magnitude = np.zeros(len(freqs))
        magnitude[inside] = np.sqrt(density * rate * n / 2.0)
        phases = np.random.default_rng([residual.seed, index]).uniform(0.0, 2 * np.pi,
                                                                       len(freqs))
        noise = np.fft.irfft(magnitude * np.exp(1j * phases), n=n)[:segment]
        if fade:
            noise[:fade] *= fade_in
            noise[-fade:] *= fade_in[::-1]
        positions = (index * length - fade // 2 + np.arange(segment)) % total
        np.add.at(out, positions, noise)
    return out
