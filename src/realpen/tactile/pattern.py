"""Tactile pattern synthesis: principal frequencies → equalised, superposed, looping pattern.

Per sub-pattern (one selected unit sequence) one sinusoid is superposed per principal
frequency, with amplitude ∝ √(power ratio) × w(f) (energy-preserving; ``amplitude="power"`` is
the literal reading, ∝ power ratio × w(f)) and a seeded random phase, which keeps the crest
factor low. A frequency that persists into the next sub-pattern keeps its phase there
(see :mod:`realpen.tracks`), so crossfades never make it dip. The power ratio is the component's share of its own sub-pattern's total, so every
sub-pattern carries the same total level and the fluctuation lies in its frequency content.

Sub-patterns follow each other (15 × 100 ms = 1500 ms by default) and the pattern loops. With
``boundary="crossfade"`` each sub-pattern is synthesised ``crossfade_ms`` longer and neighbours
(the last and the first included, across the loop wrap) overlap — continuing components with a
linear fade, the others with an equal-power fade — so the loop has no click; ``boundary="hard"`` concatenates, as the method describes literally.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from realpen import __version__
from realpen.tactile.actuator import Actuator, weighting
from realpen.errors import RealPenError, require_number
from realpen.io.recording import Recording
from realpen.dsp.filters import prepare
from realpen.dsp.spectrum import Analysis, ProgressCallback, analyze
from realpen.dsp.tracks import continuous_phases, joins, link_components

# Study 1 conditions: (principal frequencies, sub-patterns, unit length in ms).
CONDITIONS: dict[str, tuple[int, int, float]] = {
    "A": (5, 15, 100.0), "B": (10, 15, 100.0), "C": (15, 15, 100.0),
    "D": (5, 1, 1500.0), "E": (10, 1, 1500.0), "F": (15, 1, 1500.0),
}
BOUNDARIES = ("crossfade", "hard")
AMPLITUDE_MODES = ("sqrt", "power")


@dataclass(frozen=True)
class TactileParams:
    """Every parameter of the tactile pipeline (defaults: the method's condition B).

    Attributes:
        top: principal frequencies per sub-pattern (N).
        subpatterns: consecutive units in the pattern (K).
        unit_ms: unit (and sub-pattern) length in ms.
        rate: output rate in Hz.
        boundary: ``"crossfade"`` or ``"hard"``.
        crossfade_ms: crossfade length at each boundary and at the loop wrap, in ms.
        amplitude: ``"sqrt"`` (∝ √power ratio) or ``"power"`` (∝ power ratio).
        seed: seed of the random phases.
        cap_db: cap of the actuator weighting in dB.
        headroom_db: peak level below full scale after normalisation, in dB.
        selection: ``"stationary"`` or ``"middle"`` (which consecutive units).
        highpass_hz: high-pass cutoff in Hz; also the lower edge of the peak band.
        fmax_hz: upper edge of the peak band in Hz (None: Nyquist of the analysis rate).
        axis: how axes become one (None: DFT321 for several axes).
        analysis_rate: resample to this rate in Hz before analysis (None: native rate).
        condition: the study condition the counts came from, if any.
    """

    top: int = 10
    subpatterns: int = 15
    unit_ms: float = 100.0
    rate: int = 8000
    boundary: str = "crossfade"
    crossfade_ms: float = 5.0
    amplitude: str = "sqrt"
    seed: int = 0
    cap_db: float = 20.0
    headroom_db: float = 1.0
    selection: str = "stationary"
    highpass_hz: float = 30.0
    fmax_hz: float | None = None
    axis: str | None = None
    analysis_rate: float | None = None
    condition: str | None = None

    def __post_init__(self) -> None:
        if self.boundary not in BOUNDARIES:
            raise RealPenError(f"--boundary: unknown boundary '{self.boundary}' "
                               f"(choose from {', '.join(BOUNDARIES)})")
        if self.amplitude not in AMPLITUDE_MODES:
            raise RealPenError(f"--amplitude: unknown mode '{self.amplitude}' "
                               f"(choose from {', '.join(AMPLITUDE_MODES)})")
        require_number("--unit-ms", self.unit_ms, minimum=0.0, inclusive=False)
        require_number("--top", self.top, minimum=1)
        require_number("--subpatterns", self.subpatterns, minimum=1)
        require_number("--rate", self.rate, minimum=0, inclusive=False)
        require_number("--crossfade-ms", self.crossfade_ms, minimum=0.0, maximum=self.unit_ms)
        require_number("--cap-db", self.cap_db, minimum=0.0)
        require_number("--headroom-db", self.headroom_db, minimum=0.0)
        require_number("--seed", self.seed, minimum=0)
        require_number("--highpass", self.highpass_hz, minimum=0.0)
        if self.fmax_hz is not None:
            require_number("--fmax", self.fmax_hz, minimum=self.highpass_hz, inclusive=False)
        if self.analysis_rate is not None:
            require_number("--analysis-rate", self.analysis_rate, minimum=0.0, inclusive=False)

    @classmethod
    def for_condition(cls, condition: str, **overrides) -> "TactileParams":
        """Parameters of a study condition A–F, with other fields overridden."""
        key = condition.strip().upper()
        if key not in CONDITIONS:
            raise RealPenError(f"--condition: unknown condition '{condition}' (choose from "
                               f"{', '.join(CONDITIONS)})")
        top, subpatterns, unit_ms = CONDITIONS[key]
        return cls(top=top, subpatterns=subpatterns, unit_ms=unit_ms, condition=key, **overrides)


    @classmethod
    def resolve(cls, condition: str | None, top: int | None = None, subpatterns: int | None = None,
                unit_ms: float | None = None, **options) -> "TactileParams":
        """A condition preset or explicit counts (unset counts keep the defaults); not both."""
        explicit = {key: value for key, value in
                    (("top", top), ("subpatterns", subpatterns), ("unit_ms", unit_ms))
                    if value is not None}
        if condition is None:
            # With no counts given the defaults are condition B, and the record says so.
            return cls(**explicit, **options) if explicit else cls.for_condition("B", **options)
        if explicit:
            names = ", ".join("--" + key.replace("_", "-") for key in explicit)
            raise RealPenError(f"--condition sets the counts; do not combine it with {names}")
        return cls.for_condition(condition, **options)


@dataclass(frozen=True)
class Component:
    """One sinusoid of a sub-pattern.

    Attributes:
        frequency_hz: frequency in Hz.
        power: mean-square power measured in the recording (recording unit squared).
        weight: actuator weighting w(f) (dimensionless).
        amplitude: amplitude in the output pattern (full scale = 1).
        phase: phase in radians at the start of the sub-pattern.
        clipped: whether the weighting cap limited this component.
        joins_previous: it continues a component of the previous sub-pattern (same track,
            continuous phase), so the crossfade into it is linear in amplitude.
        joins_next: it continues into the next sub-pattern, likewise.
    """

    frequency_hz: float
    power: float
    weight: float
    amplitude: float
    phase: float
    clipped: bool = False
    joins_previous: bool = False
    joins_next: bool = False


@dataclass
class Pattern:
    """A looping tactile pattern and everything that made it.

    Attributes:
        samples: the pattern, shape (frames,), full scale ±1; loops seamlessly.
        rate: sample rate in Hz.
        subpatterns: components of each sub-pattern, in order.
        params: the parameters used.
        actuator: the actuator the pattern is equalised for.
        analysis: the analysis of the source recording (None when built from components).
        gain: the normalisation gain applied to the relative amplitudes.
        source: the source recording's path; source_sha256 its SHA-256.
        notes: things the user should know (e.g. components limited by the cap).
        source_info: the source recording's rate (Hz), axes, units and processing history.
    """

    samples: np.ndarray
    rate: int
    subpatterns: list[list[Component]]
    params: TactileParams
    actuator: Actuator
    analysis: Analysis | None = None
    gain: float = 1.0
    source: str | None = None
    source_sha256: str | None = None
    notes: list[str] = field(default_factory=list)
    source_info: dict | None = None

    @property
    def duration_s(self) -> float:
        """Pattern length in seconds."""
        return len(self.samples) / self.rate

    @property
    def clipped_count(self) -> int:
        """How many components the weighting cap limited."""
        return sum(c.clipped for sub in self.subpatterns for c in sub)

    def to_json(self) -> dict:
        """The ``realpen tactile --json`` document."""
        analysis = None
        if self.analysis is not None:
            analysis = {"rate": self.analysis.rate,
                        "selected_units": [int(i) for i in self.analysis.selected],
                        "selected_start_s": [round(float(self.analysis.starts_s[i]), 6)
                                             for i in self.analysis.selected]}
        return {
            "realpen_version": __version__,
            "source": {"path": self.source, "sha256": self.source_sha256,
                       **(self.source_info or {})},
            "parameters": asdict(self.params),
            "actuator": self.actuator.to_json(),
            "rate": self.rate,
            "frames": int(len(self.samples)),
            "duration_s": self.duration_s,
            "subpattern_ms": self.params.unit_ms,
            "gain": self.gain,
            "weighting": {"cap_db": self.params.cap_db, "clipped_components": self.clipped_count},
            "analysis": analysis,
            "subpatterns": [[asdict(c) for c in sub] for sub in self.subpatterns],
            "notes": self.notes,
        }


def synthesize(subpatterns: list[list[Component]] | list[tuple[np.ndarray, ...]],
               rate: int, subpattern_ms: float, boundary: str = "crossfade",
               crossfade_ms: float = 5.0) -> np.ndarray:
    """Superpose sinusoids per sub-pattern and join the sub-patterns into one loop.

    Args:
        subpatterns: per sub-pattern either a list of :class:`Component` or a tuple of arrays
            (frequencies in Hz, amplitudes, phases in radians[, joins_previous, joins_next]).
        rate: output rate in Hz.
        subpattern_ms: length of each sub-pattern in ms.
        boundary: ``"crossfade"`` (across the loop wrap too) or ``"hard"``.
        crossfade_ms: fade length in ms. A component that continues a track across a
            boundary fades linearly (its two halves are in phase); any other fades with equal
            power (sin/cos), as uncorrelated material should.

    Returns:
        The loop, shape (len(subpatterns) × subpattern samples,).
    """
    length = int(round(subpattern_ms * rate / 1000.0))
    total = length * len(subpatterns)
    fade = int(round(crossfade_ms * rate / 1000.0)) if boundary == "crossfade" else 0
    fade -= fade % 2  # even, so the fade is centred on the boundary
    fade = min(fade, length)
    out = np.zeros(total)
    local = (np.arange(length + fade) - fade // 2) / rate
    u = (np.arange(fade) + 0.5) / max(fade, 1)
    power_in, linear_in = np.sin(0.5 * np.pi * u), u
    for index, sub in enumerate(subpatterns):
        freqs, amps, phases, joins_previous, joins_next = _arrays(sub)
        waves = amps[:, None] * np.sin(2 * np.pi * freqs[:, None] * local[None, :] + phases[:, None])
        if fade:
            waves[:, :fade] *= np.where(joins_previous[:, None], linear_in, power_in)
            waves[:, -fade:] *= np.where(joins_next[:, None], linear_in[::-1], power_in[::-1])
        positions = (index * length - fade // 2 + np.arange(length + fade)) % total
        np.add.at(out, positions, waves.sum(axis=0))
    return out


def _arrays(sub) -> tuple[np.ndarray, ...]:
    if isinstance(sub, tuple):
        arrays = [np.asarray(a, dtype=np.float64) for a in sub[:3]]
        flags = [np.asarray(a, dtype=bool) for a in sub[3:5]]
        flags += [np.zeros(len(arrays[0]), dtype=bool)] * (2 - len(flags))
        return (*arrays, *flags)
    return (np.array([c.frequency_hz for c in sub], dtype=np.float64),
            np.array([c.amplitude for c in sub], dtype=np.float64),
            np.array([c.phase for c in sub], dtype=np.float64),
            np.array([c.joins_previous for c in sub], dtype=bool),
            np.array([c.joins_next for c in sub], dtype=bool))


def build_pattern(recording: Recording, actuator: Actuator, params: TactileParams = TactileParams(),
                  progress: ProgressCallback | None = None) -> Pattern:
    """Run the tactile pipeline on a loaded recording.

    Preprocess (axes → one, optional resampling, high-pass), analyse unit sequences, select K
    consecutive units, weight each unit's top-N peaks for the actuator, and synthesise the loop.

    Raises:
        RealPenError: any problem with the recording or the parameters.
    """
    prepared = prepare(recording, params.axis, params.analysis_rate, params.highpass_hz)
    analysis = analyze(prepared.mono, prepared.rate, params.unit_ms, params.top,
                       params.subpatterns, params.selection, fmin=params.highpass_hz,
                       fmax=params.fmax_hz, source=recording.source, progress=progress)
    if np.nanmax(analysis.frequencies_hz[analysis.selected]) >= params.rate / 2:
        raise RealPenError(f"--rate: {params.rate} Hz is too low for components up to "
                           f"{np.nanmax(analysis.frequencies_hz[analysis.selected]):.0f} Hz")
    band = (params.highpass_hz, params.fmax_hz or prepared.rate / 2)
    rng = np.random.default_rng(params.seed)
    units = [analysis.unit(int(unit)) for unit in analysis.selected]
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
    peak = float(np.max(np.abs(raw)))
    if not np.isfinite(peak) or peak <= 0:
        raise RealPenError(f"{recording.source}: the pattern came out silent or not finite; "
                           f"check the actuator and weighting parameters")
    gain = 10 ** (-params.headroom_db / 20) / peak
    subpatterns = [[Component(float(f), float(pw), float(w), float(a * gain), float(p), bool(c),
                              bool(jp), bool(jn))
                    for f, pw, w, a, p, c, jp, jn in zip(*sub)] for sub in relative]
    notes = []
    info = {"rate_hz": recording.rate, "axes": list(recording.axes), "units": recording.units,
            "frames": int(recording.samples.shape[0]), "history": list(prepared.history)}
    pattern = Pattern(raw * gain, params.rate, subpatterns, params, actuator, analysis, gain,
                      recording.source, recording.sha256, notes, info)
    if pattern.clipped_count:
        notes.append(f"{pattern.clipped_count} component(s) limited by the {params.cap_db:g} dB "
                     f"weighting cap")
    return pattern
