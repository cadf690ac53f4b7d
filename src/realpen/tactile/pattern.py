"""The one tactile-pattern type: :class:`TactilePattern` made of :class:`Component` sinusoids.

A tactile pattern is a loop of sub-patterns (15 × 100 ms for the method's condition B), each a
superposition of sinusoids ``a·sin(2πf·t + φ)``, joined by crossfades (or hard boundaries).
That description — the components per sub-pattern, the rate, the sub-pattern length and the
boundary — *is* the pattern: :meth:`TactilePattern.render` synthesises it at any rate,
:attr:`TactilePattern.samples` is the rendering at its own rate, ``profile.json`` stores exactly
these fields (:meth:`TactilePattern.to_json`), and every export reads them.

A pattern may also carry a stochastic :class:`~realpen.tactile.residual.Residual` (model
``"sines+residual"``): band levels per sub-pattern of a noise added to the sinusoids. It is part
of the pattern (JSON, equality, version); a pattern without one writes no ``residual`` key, so
every pattern made before it existed keeps its JSON and version byte for byte.

A pattern built from a recording (:func:`realpen.tactile.build.build_pattern`) also carries
where it came from: the actuator it is equalised for, the parameters, the analysis and the
source's provenance. Those are not part of its identity (equality and :attr:`version` look at
the components, the residual and the lengths only).

Versions are SHA-256 hashes of a canonical JSON form (:func:`canonical_json`: floats rounded to
9 significant digits, keys sorted, compact), so the same pattern has the same version on every
machine even when the last bits of its floats differ.

numpy only: this module is imported by the profile schema.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from realpen.checks import (
    MAX_COMPONENTS,
    MAX_RATE_HZ,
    MAX_SUBPATTERNS,
    MAX_TOP,
    MAX_UNIT_MS,
    check_frames,
    check_pattern_rate,
    require_choice,
    require_number,
)
from realpen.errors import ParameterError
from realpen.tactile.actuator import Actuator
from realpen.tactile.conditions import TactileParams
from realpen.tactile.residual import Residual, render_residual
from realpen.tactile.synthesis import BOUNDARIES, subpattern_samples, synthesize

if TYPE_CHECKING:
    from realpen.dsp.spectrum import Analysis

__all__ = ["Component", "TactilePattern", "canonical_json", "content_version", "json_fields",
           "SIGNIFICANT_DIGITS", "MAX_SUBPATTERN_MS"]

SIGNIFICANT_DIGITS = 9
MAX_SUBPATTERN_MS = MAX_UNIT_MS  # ms; a sub-pattern is one analysed unit (or the D–F stretch)
NOT_JSON = {"json": False}  # field metadata: not stored in profile.json


def _canonical(value: Any) -> Any:
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if not math.isfinite(value):
            raise ParameterError("value", f"{value} has no canonical JSON form")
        return float(f"{value:.{SIGNIFICANT_DIGITS}g}") + 0.0  # + 0.0: no negative zero
    if isinstance(value, dict):
        return {str(key): _canonical(item) for key, item in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_canonical(item) for item in value]
    raise ParameterError("value", f"{type(value).__name__} has no canonical JSON form")


def canonical_json(value: Any) -> bytes:
    """The canonical JSON bytes of a JSON-ready value, for hashing.

    Every float is rounded to :data:`SIGNIFICANT_DIGITS` (9) significant digits (and −0.0
    becomes 0.0), keys are sorted, separators are compact, text is UTF-8. Floats that differ
    only in their last bits (numpy/scipy versions, CPUs) therefore give the same bytes.

    Example:
        >>> canonical_json({"b": 270.28028653691086, "a": [1, True]})
        b'{"a":[1,true],"b":270.280287}'
    """
    return json.dumps(_canonical(value), sort_keys=True, separators=(",", ":"),
                      ensure_ascii=False, allow_nan=False).encode("utf-8")


def content_version(value: Any, digits: int = 12) -> str:
    """The first ``digits`` hex digits of the SHA-256 of :func:`canonical_json` of ``value``."""
    return hashlib.sha256(canonical_json(value)).hexdigest()[:digits]


def json_fields(cls: type) -> list:
    """The dataclass fields of ``cls`` that its JSON form (and ``profile.json``) holds."""
    return [item for item in fields(cls) if item.metadata.get("json", True)]


def _finite(name: str, value: Any, minimum: float | None = None, inclusive: bool = True) -> float:
    require_number(name, value, minimum=minimum, inclusive=inclusive)
    return float(value)


@dataclass(frozen=True, repr=False)
class Component:
    """One sinusoid of a sub-pattern: ``amplitude · sin(2π·frequency_hz·t + phase)``.

    ``t`` is counted in seconds from the start of its sub-pattern.

    Attributes:
        frequency_hz: frequency in Hz (> 0).
        amplitude: amplitude in the output pattern, full scale = 1 (≥ 0).
        phase: phase in radians at the start of the sub-pattern.
        power: mean-square power measured in the recording (recording unit squared), if known.
        weight: actuator weighting w(f) (dimensionless), if known.
        clipped: whether the weighting cap limited this component.
        joins_previous: it continues a component of the previous sub-pattern (same track,
            continuous phase), so the crossfade into it is linear in amplitude.
        joins_next: it continues into the next sub-pattern, likewise.

    Example:
        >>> Component(175.0, 0.5)
        Component(175 Hz, amplitude 0.5, phase 0 rad)
    """

    frequency_hz: float = field(metadata={"schema": {"gt": 0}})
    amplitude: float = field(metadata={"schema": {"ge": 0}})
    phase: float = 0.0
    power: float | None = field(default=None, metadata={"schema": {"ge": 0}})
    weight: float | None = field(default=None, metadata={"schema": {"ge": 0}})
    clipped: bool = False
    joins_previous: bool = False
    joins_next: bool = False

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "frequency_hz", _finite("frequency_hz", self.frequency_hz, 0.0, False))
        if self.frequency_hz > MAX_RATE_HZ / 2:  # no pattern RealPen writes could hold it
            raise ParameterError("frequency_hz", f"must be <= {MAX_RATE_HZ / 2:g} Hz (half the "
                                                 f"highest rate), got {self.frequency_hz:g}")
        set_(self, "amplitude", _finite("amplitude", self.amplitude, 0.0))
        set_(self, "phase", _finite("phase", self.phase))
        for name in ("power", "weight"):
            if getattr(self, name) is not None:
                set_(self, name, _finite(name, getattr(self, name), 0.0))
        for name in ("clipped", "joins_previous", "joins_next"):
            value = getattr(self, name)
            if not isinstance(value, (bool, np.bool_)):
                raise ParameterError(name, f"must be True or False, got {value!r}")
            set_(self, name, bool(value))

    def __repr__(self) -> str:
        flags = [name.replace("_", " ") for name in ("clipped", "joins_previous", "joins_next")
                 if getattr(self, name)]
        return (f"Component({self.frequency_hz:.6g} Hz, amplitude {self.amplitude:.4g}, "
                f"phase {self.phase:.4g} rad{''.join(', ' + flag for flag in flags)})")

    def to_json(self) -> dict:
        """Every field, in order (``profile.json``'s form of a component)."""
        return {item.name: getattr(self, item.name) for item in fields(self)}

    @classmethod
    def from_json(cls, data: dict) -> Component:
        """A component from :meth:`to_json`'s form (missing optional fields take defaults).

        Raises:
            ParameterError: unknown or missing fields, or bad values.
        """
        if isinstance(data, Component):
            return data
        if not isinstance(data, dict):
            raise ParameterError("subpatterns", f"a component must be an object, got "
                                                f"{type(data).__name__}")
        unknown = sorted(set(data) - {item.name for item in fields(cls)})
        if unknown:
            raise ParameterError("subpatterns", f"unknown component field(s) {', '.join(unknown)}")
        try:
            return cls(**data)
        except TypeError:
            raise ParameterError("subpatterns", "a component needs frequency_hz and "
                                                "amplitude") from None


@dataclass(frozen=True, repr=False)
class TactilePattern:
    """A looping tactile pattern: components per sub-pattern, rate, lengths, boundaries.

    Attributes:
        subpatterns: the components of each sub-pattern, in playing order (each a tuple of
            :class:`Component`; lists and JSON dicts are accepted and converted).
        rate: the pattern's own rate in Hz (the rate of :attr:`samples`).
        subpattern_ms: length of each sub-pattern in ms.
        boundary: ``"crossfade"`` or ``"hard"`` (see :mod:`realpen.tactile.synthesis`).
        crossfade_ms: crossfade length at each boundary and at the loop wrap, in ms.
        actuator: the actuator the amplitudes are equalised for, if known.
        params: the :class:`~realpen.tactile.conditions.TactileParams` it was built with.
        analysis: the analysis of the source recording (:class:`realpen.dsp.spectrum.Analysis`;
            ``analysis.selected`` are the units of the stretch it was made from).
        provenance: the source recording (``path``, ``sha256``, ``rate_hz``, ``axes``, ``units``,
            ``frames``, ``history``), the normalisation ``gain`` and ``stretch_s`` (start and
            end in s of the analysed stretch), when built from a recording.
        notes: things the user should know (e.g. components limited by the weighting cap).
        residual: the stochastic residual added to the sinusoids
            (:class:`~realpen.tactile.residual.Residual`, one row of band levels per
            sub-pattern; a JSON dict is accepted), or None (the method's sines only).

    The first five fields and ``residual`` are the pattern (``profile.json`` stores them;
    equality and :attr:`version` use them); the others say where it came from. ``residual``
    comes last so that positional calls written before it existed keep their meaning.

    Limits (a :class:`~realpen.errors.ParameterError` otherwise, before anything is
    synthesised): at most :data:`~realpen.checks.MAX_SUBPATTERNS` sub-patterns of at most
    :data:`~realpen.checks.MAX_TOP` components, each at most :data:`MAX_SUBPATTERN_MS` ms,
    and a loop of at most :data:`~realpen.checks.MAX_PATTERN_FRAMES` samples.

    Example:
        >>> pattern = TactilePattern([[Component(175.0, 0.5)], [Component(180.0, 0.4)]])
        >>> pattern
        TactilePattern(2 sub-patterns × 100 ms, 1 component each, 8000 Hz)
        >>> pattern.render(44100).shape
        (8820,)
    """

    subpatterns: tuple[tuple[Component, ...], ...]
    rate: int = field(default=8000, metadata={"schema": {"gt": 0}})
    subpattern_ms: float = field(default=100.0, metadata={"schema": {
        "gt": 0, "le": MAX_SUBPATTERN_MS}})
    boundary: str = field(default="crossfade", metadata={"choices": BOUNDARIES})
    crossfade_ms: float = field(default=5.0, metadata={"schema": {"ge": 0}})
    actuator: Actuator | None = field(default=None, compare=False, metadata=NOT_JSON)
    params: TactileParams | None = field(default=None, compare=False, metadata=NOT_JSON)
    analysis: Analysis | None = field(default=None, compare=False, metadata=NOT_JSON)
    provenance: dict = field(default_factory=dict, compare=False, metadata=NOT_JSON)
    notes: tuple[str, ...] = field(default=(), compare=False, metadata=NOT_JSON)
    residual: Residual | None = None
    _samples: np.ndarray | None = field(default=None, init=False, compare=False,
                                        metadata=NOT_JSON)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if isinstance(self.subpatterns, (str, bytes, dict)) or not len(self.subpatterns):
            raise ParameterError("subpatterns", "needs at least one sub-pattern")
        if len(self.subpatterns) > MAX_SUBPATTERNS:
            raise ParameterError("subpatterns", f"{len(self.subpatterns):,} sub-patterns; a "
                                                f"pattern holds at most {MAX_SUBPATTERNS}")
        subpatterns = []
        for index, sub in enumerate(self.subpatterns):
            if isinstance(sub, (str, bytes, dict)) or not len(sub):
                raise ParameterError("subpatterns", f"sub-pattern {index} needs at least one "
                                                    f"component")
            if len(sub) > MAX_TOP:
                raise ParameterError("subpatterns", f"sub-pattern {index} has {len(sub):,} "
                                                    f"components; the limit is {MAX_TOP}")
            subpatterns.append(tuple(Component.from_json(c) for c in sub))
        total = sum(len(sub) for sub in subpatterns)
        if total > MAX_COMPONENTS:
            raise ParameterError("subpatterns", f"the pattern has {total:,} components in all; "
                                                f"the limit is {MAX_COMPONENTS:,}")
        set_(self, "subpatterns", tuple(subpatterns))
        set_(self, "rate", check_pattern_rate(self.rate))
        set_(self, "subpattern_ms", _finite("subpattern_ms", self.subpattern_ms, 0.0, False))
        require_number("subpattern_ms", self.subpattern_ms, maximum=MAX_SUBPATTERN_MS)
        require_choice("boundary", self.boundary, BOUNDARIES)
        set_(self, "crossfade_ms", _finite("crossfade_ms", self.crossfade_ms, 0.0))
        require_number("crossfade_ms", self.crossfade_ms, maximum=self.subpattern_ms)
        if subpattern_samples(self.rate, self.subpattern_ms) < 1:
            raise ParameterError("subpattern_ms", f"{self.subpattern_ms:g} ms is less than one "
                                                  f"sample at {self.rate} Hz")
        check_frames(len(self.subpatterns), self.rate, self.subpattern_ms, "subpatterns")
        if self.actuator is not None and not isinstance(self.actuator, Actuator):
            raise ParameterError("actuator", f"must be an Actuator, got "
                                             f"{type(self.actuator).__name__}")
        if self.residual is not None:
            set_(self, "residual", Residual.from_json(self.residual))
            if len(self.residual.levels) != len(self.subpatterns):
                raise ParameterError("residual", f"has the levels of "
                                                 f"{len(self.residual.levels)} sub-pattern(s); "
                                                 f"the pattern has {len(self.subpatterns)}")
            if self.residual.band_edges_hz[-1] > self.rate / 2:
                raise ParameterError("residual", f"has bands up to "
                                                 f"{self.residual.band_edges_hz[-1]:g} Hz, above "
                                                 f"half the pattern's {self.rate} Hz")
            loudest = float(np.max(self.residual.powers))
            if loudest > 1.0:  # noise louder than a full-scale square wave cannot be played
                raise ParameterError("residual", f"carries a mean-square power of {loudest:.3g} in "
                                                 f"a sub-pattern; at most 1 (full scale)")
        set_(self, "provenance", dict(self.provenance or {}))
        set_(self, "notes", tuple(self.notes))

    # --- what it is -----------------------------------------------------------------------

    @property
    def frames(self) -> int:
        """Length of one loop in samples at :attr:`rate`."""
        return self.frames_at(self.rate)

    def frames_at(self, rate: float) -> int:
        """Length of one loop in samples at ``rate`` Hz."""
        return subpattern_samples(rate, self.subpattern_ms) * len(self.subpatterns)

    @property
    def duration_s(self) -> float:
        """Loop length in seconds (whole samples at :attr:`rate`)."""
        return self.frames / self.rate

    @property
    def components(self) -> list[Component]:
        """Every component of every sub-pattern, in order."""
        return [c for sub in self.subpatterns for c in sub]

    @property
    def max_frequency_hz(self) -> float:
        """The highest component frequency in Hz."""
        return max(c.frequency_hz for c in self.components)

    @property
    def clipped_count(self) -> int:
        """How many components the weighting cap limited."""
        return sum(c.clipped for c in self.components)

    @property
    def gain(self) -> float | None:
        """The normalisation gain applied to the relative amplitudes, when built here."""
        return self.provenance.get("gain")

    @property
    def source(self) -> str | None:
        """The source recording's path, when built from one."""
        return self.provenance.get("path")

    @property
    def stretch_s(self) -> tuple[float, float] | None:
        """Start and end in s of the stretch of the recording it was made from, if known."""
        stretch = self.provenance.get("stretch_s")
        return None if stretch is None else (float(stretch[0]), float(stretch[1]))

    @property
    def version(self) -> str:
        """12 hex digits of the SHA-256 of the canonical form of :meth:`to_json`."""
        return content_version(self.to_json())

    def __repr__(self) -> str:
        counts = sorted({len(sub) for sub in self.subpatterns})
        each = (f"{counts[0]} component{'s' if counts[0] != 1 else ''} each" if len(counts) == 1
                else f"{counts[0]}–{counts[-1]} components")
        extra = "" if self.boundary == "crossfade" else ", hard boundaries"
        if self.residual is not None:
            extra += f", residual in {self.residual.bands} bands"
        if self.actuator is not None:
            spec = self.actuator.spec if self.actuator.kind != "measured" else \
                "measured " + Path(self.actuator.spec).name
            extra += f", {spec[:60]}"
        count = len(self.subpatterns)
        return (f"TactilePattern({count} sub-pattern{'s' if count != 1 else ''} × "
                f"{self.subpattern_ms:g} ms, {each}, {self.rate} Hz{extra})")

    # --- samples --------------------------------------------------------------------------

    def render(self, rate: float | None = None) -> np.ndarray:
        """Synthesise one loop at ``rate`` Hz (default: :attr:`rate`).

        Sub-patterns are ``round(subpattern_ms × rate / 1000)`` samples long at any rate, so a
        rate that makes the sub-pattern a whole number of samples keeps the lengths exact.
        The residual, if any, is added (:func:`~realpen.tactile.residual.render_residual`): the
        same noise at the same rate every time, another realisation of the same spectrum at
        another rate, without its bands above ``rate / 2``.

        Returns:
            float64 array, shape (:meth:`frames_at` ``(rate)``,), full scale ±1.

        Raises:
            ParameterError: ``rate`` is not positive, or not above twice the highest component
                frequency (the components would alias).
        """
        rate = self.rate if rate is None else rate
        require_number("rate", rate, minimum=0.0, inclusive=False, maximum=MAX_RATE_HZ)
        if self.max_frequency_hz >= rate / 2:
            raise ParameterError("rate", f"{rate:g} Hz is too low for components up to "
                                         f"{self.max_frequency_hz:.0f} Hz (needs more than "
                                         f"{2 * self.max_frequency_hz:.0f} Hz)")
        out = synthesize(self.subpatterns, rate, self.subpattern_ms, self.boundary,
                         self.crossfade_ms)
        if self.residual is not None:
            out += render_residual(self.residual, rate, self.subpattern_ms, self.crossfade_ms,
                                   len(self.subpatterns))
        return out

    @property
    def samples(self) -> np.ndarray:
        """The pattern at its own rate, shape (:attr:`frames`,), full scale ±1.

        The samples it was built or loaded with (a profile's ``tactile.wav``), else
        :meth:`render` ``()`` (computed once).
        """
        if self._samples is None:
            object.__setattr__(self, "_samples", self.render())
        return self._samples

    def with_samples(self, samples: np.ndarray) -> TactilePattern:
        """A copy whose :attr:`samples` are ``samples`` (e.g. the WAV it was saved as).

        Raises:
            ParameterError: ``samples`` is not one loop (:attr:`frames` values) of finite numbers.
        """
        samples = np.asarray(samples)
        if samples.ndim != 1 or len(samples) != self.frames:
            raise ParameterError("samples", f"must be one loop of {self.frames} samples at "
                                            f"{self.rate} Hz, got shape {samples.shape}")
        if not np.all(np.isfinite(samples)):
            raise ParameterError("samples", "contains NaN or infinite values")
        copy = replace(self)
        object.__setattr__(copy, "_samples", samples)
        return copy

    # --- JSON -----------------------------------------------------------------------------

    def to_json(self) -> dict:
        """The pattern's own fields, JSON-ready: ``rate``, ``subpattern_ms``, ``boundary``,
        ``crossfade_ms``, ``subpatterns`` (lists of :meth:`Component.to_json`) and, only when
        there is one, ``residual`` (:meth:`Residual.to_json`). This is ``profile.json``'s
        ``tactile`` section; :meth:`from_json` reads it back."""
        data = {}
        for item in json_fields(type(self)):
            if item.name not in ("subpatterns", "residual"):
                data[item.name] = getattr(self, item.name)
        data["subpatterns"] = [[c.to_json() for c in sub] for sub in self.subpatterns]
        if self.residual is not None:  # absent, not null: older patterns keep their JSON
            data["residual"] = self.residual.to_json()
        return data

    @classmethod
    def from_json(cls, data: dict, **origin) -> TactilePattern:
        """A pattern from :meth:`to_json`'s form; ``origin`` sets the non-JSON fields
        (``actuator``, ``params``, ``analysis``, ``provenance``, ``notes``). A missing
        ``residual`` is None.

        Raises:
            ParameterError: unknown fields or bad values.
        """
        if not isinstance(data, dict):
            raise ParameterError("pattern", f"must be a JSON object, got {type(data).__name__}")
        names = {item.name for item in json_fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ParameterError("pattern", f"unknown field(s) {', '.join(unknown)}")
        if "subpatterns" not in data:
            raise ParameterError("subpatterns", "is missing")
        return cls(**data, **origin)

    def report(self) -> dict:
        """The JSON report of ``realpen tactile``: the pattern, its parameters, actuator,
        source and analysis, and notes."""
        from realpen._version import __version__

        analysis = None
        if self.analysis is not None:
            selected = [int(i) for i in self.analysis.selected]
            analysis = {"rate": self.analysis.rate, "unit_ms": self.analysis.unit_ms,
                        "selected_units": selected,
                        "selected_start_s": [round(float(self.analysis.starts_s[i]), 6)
                                             for i in selected],
                        "stretch_s": None if self.stretch_s is None
                        else [round(v, 6) for v in self.stretch_s]}
        source = {key: value for key, value in self.provenance.items()
                  if key not in ("gain", "stretch_s")}
        source["path"], source["sha256"] = source.get("path"), source.get("sha256")
        cap_db = self.params.cap_db if self.params is not None else None
        return {
            "realpen_version": __version__,
            "version": self.version,
            "source": source,
            "parameters": None if self.params is None else self.params.to_json(),
            "actuator": None if self.actuator is None else self.actuator.to_json(),
            "rate": self.rate,
            "frames": self.frames,
            "duration_s": self.duration_s,
            "subpattern_ms": self.subpattern_ms,
            "boundary": self.boundary,
            "crossfade_ms": self.crossfade_ms,
            "gain": self.gain,
            "weighting": {"cap_db": cap_db, "clipped_components": self.clipped_count},
            "analysis": analysis,
            "subpatterns": [[c.to_json() for c in sub] for sub in self.subpatterns],
            **({} if self.residual is None else {"residual": self.residual.to_json()}),
            "notes": list(self.notes),
        }
