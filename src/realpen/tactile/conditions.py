"""The parameters of the tactile pipeline and the study conditions A–F.

Study 1 of the method varies two things: the number of principal frequencies (5, 10 or 15) and
whether the pattern fluctuates (15 sub-patterns of 100 ms: A, B, C) or not (one pattern of
1500 ms: D, E, F). Everything else is the same, so all six are built from the *same* 1500 ms
stretch of the recording: 15 consecutive 100 ms units chosen exactly as for A–C (first and last
unit never, the most stationary run or the middle one). A–C analyse each unit on its own; D–F
analyse the 15 units' concatenation as one unit (``selection_unit_ms=100`` with
``unit_ms=1500``). Any recording that serves B therefore serves all six.

A condition sets the counts. ``TactileParams(condition="D")`` has D's ``top``, ``subpatterns``
and ``unit_ms``; giving a condition together with a count that disagrees with it is refused.

Only numpy-free code here (:mod:`realpen.checks`, :mod:`realpen.defaults`, the errors); importing
it is cheap. The conditions and the models are defined in :mod:`realpen.defaults`, which the
command line's help reads without loading numpy.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

from realpen.checks import (
    MAX_CAP_DB,
    MAX_RATE_HZ,
    MAX_SEED,
    MAX_SUBPATTERNS,
    MAX_TOP,
    MAX_UNIT_MS,
    MIN_RATE_HZ,
    check_frames,
    check_pattern_rate,
    require_choice,
    require_number,
)
from realpen.defaults import CONDITIONS, RECOMMENDED_MODEL, TACTILE_MODELS
from realpen.errors import ParameterError
from realpen.tactile.synthesis import BOUNDARIES, subpattern_samples

__all__ = ["CONDITIONS", "SELECTION_UNIT_MS", "AMPLITUDE_MODES", "SELECTIONS", "MODELS", "RECOMMENDED_MODEL",
           "TactileParams"]

SELECTION_UNIT_MS = 100.0  # the unit sequence every condition's stretch is chosen in
AMPLITUDE_MODES = ("sqrt", "power")
SELECTIONS = ("stationary", "middle")
MODELS = TACTILE_MODELS  # the method's sinusoids; plus the stochastic residual
_COUNTS = ("top", "subpatterns", "unit_ms")
_MAXIMA = {"top": MAX_TOP, "subpatterns": MAX_SUBPATTERNS, "unit_ms": MAX_UNIT_MS}


@dataclass(frozen=True, repr=False)
class TactileParams:
    """Every parameter of the tactile pipeline (defaults: the method's condition B).

    Attributes:
        top: principal frequencies per sub-pattern (N).
        subpatterns: sub-patterns in the pattern (K).
        unit_ms: sub-pattern length in ms (also the analysed unit's length).
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
        condition: the study condition A–F that set the counts, if any.
        selection_unit_ms: length in ms of the units the stretch is selected in; ``unit_ms``
            must be a whole multiple of it, and each sub-pattern analyses that many
            consecutive selected units as one (None: ``unit_ms``; D–F: 100 ms).
        model: ``"sines"`` (the method: principal frequencies only) or ``"sines+residual"``
            (plus the stochastic residual, :mod:`realpen.tactile.residual`). The study
            conditions A–F are the method's and use ``"sines"``.

    Example:
        >>> TactileParams(condition="D").top, TactileParams(condition="D").unit_ms
        (5, 1500.0)
        >>> TactileParams(condition="D", top=10)
        Traceback (most recent call last):
        ...
        realpen.errors.ParameterError: top: condition D sets 5, not 10 (give the condition or the counts)

    Raises:
        ParameterError: any bad value, named by its parameter. Values that size the pattern or
            its analysis are checked against their limits (:mod:`realpen.checks`: ``top``,
            ``subpatterns``, ``unit_ms``, ``seed``, ``cap_db``; ``rate`` and the loop's length
            in samples, :mod:`realpen.tactile.synthesis`; ``analysis_rate``,
            :mod:`realpen.io.limits`) before anything is computed.
    """

    top: int | None = None
    subpatterns: int | None = None
    unit_ms: float | None = None
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
    selection_unit_ms: float | None = None
    model: str = "sines"

    def __post_init__(self) -> None:
        condition = self.condition
        if condition is not None:
            if not isinstance(condition, str) or condition.strip().upper() not in CONDITIONS:
                raise ParameterError("condition", f"unknown condition {condition!r} (choose from "
                                                  f"{', '.join(CONDITIONS)})")
            condition = condition.strip().upper()
            object.__setattr__(self, "condition", condition)
        preset = dict(zip(_COUNTS, CONDITIONS[condition or "B"]))
        for name in _COUNTS:
            value = getattr(self, name)
            if value is None:
                object.__setattr__(self, name, preset[name])
                continue
            if name == "unit_ms":
                require_number(name, value, minimum=0.0, inclusive=False, maximum=MAX_UNIT_MS)
            else:
                require_number(name, value, minimum=1, maximum=_MAXIMA[name])
            if condition is not None and value != preset[name]:
                raise ParameterError(name, f"condition {condition} sets {preset[name]:g}, "
                                           f"not {value:g} (give the condition or the counts)")
        if int(self.top) != self.top:
            raise ParameterError("top", f"must be a whole number, got {self.top:g}")
        if int(self.subpatterns) != self.subpatterns:
            raise ParameterError("subpatterns", f"must be a whole number, got {self.subpatterns:g}")
        object.__setattr__(self, "top", int(self.top))
        object.__setattr__(self, "subpatterns", int(self.subpatterns))
        object.__setattr__(self, "unit_ms", float(self.unit_ms))
        one_unit = condition in ("D", "E", "F")
        if self.selection_unit_ms is None:
            object.__setattr__(self, "selection_unit_ms",
                               SELECTION_UNIT_MS if one_unit else self.unit_ms)
        elif one_unit and self.selection_unit_ms != SELECTION_UNIT_MS:
            raise ParameterError("selection_unit_ms", f"condition {condition} analyses the "
                                                      f"stretch of {SELECTION_UNIT_MS:g} ms units "
                                                      f"that B selects, not "
                                                      f"{self.selection_unit_ms:g} ms units")
        require_number("selection_unit_ms", self.selection_unit_ms, minimum=0.0, inclusive=False,
                       maximum=self.unit_ms)
        object.__setattr__(self, "selection_unit_ms", float(self.selection_unit_ms))
        ratio = self.unit_ms / self.selection_unit_ms
        if abs(ratio - round(ratio)) > 1e-9:
            raise ParameterError("selection_unit_ms", f"unit_ms ({self.unit_ms:g}) must be a whole "
                                                      f"multiple of it, got "
                                                      f"{self.selection_unit_ms:g}")
        object.__setattr__(self, "rate", check_pattern_rate(self.rate))
        if subpattern_samples(self.rate, self.unit_ms) < 1:
            # Said here: the crossfade, checked next against the unit, is not what is wrong.
            raise ParameterError("unit_ms", f"{self.unit_ms:g} ms is less than one sample at "
                                            f"{self.rate} Hz")
        check_frames(self.subpatterns, self.rate, self.unit_ms,
                     "subpatterns" if self.subpatterns > 1 else "unit_ms")
        require_choice("boundary", self.boundary, BOUNDARIES)
        require_choice("amplitude", self.amplitude, AMPLITUDE_MODES)
        require_choice("selection", self.selection, SELECTIONS)
        require_choice("model", self.model, MODELS)
        require_number("crossfade_ms", self.crossfade_ms, minimum=0.0)
        if self.crossfade_ms > self.unit_ms:
            raise ParameterError("crossfade_ms", f"{self.crossfade_ms:g} ms is longer than the "
                                                 f"{self.unit_ms:g} ms sub-pattern; shorten the "
                                                 f"crossfade or lengthen the sub-pattern")
        require_number("cap_db", self.cap_db, minimum=0.0, maximum=MAX_CAP_DB)
        require_number("headroom_db", self.headroom_db, minimum=0.0)
        require_number("seed", self.seed, minimum=0, maximum=MAX_SEED)
        require_number("highpass_hz", self.highpass_hz, minimum=0.0)
        if self.fmax_hz is not None:
            require_number("fmax_hz", self.fmax_hz, minimum=self.highpass_hz, inclusive=False)
        if self.analysis_rate is not None:  # the limits of realpen.dsp.filters.resample
            require_number("analysis_rate", self.analysis_rate, minimum=0.0, inclusive=False)
            require_number("analysis_rate", self.analysis_rate, minimum=MIN_RATE_HZ,
                           maximum=MAX_RATE_HZ)

    def __repr__(self) -> str:
        shown = [f"condition={self.condition!r}"] if self.condition else []
        shown += [f"top={self.top}", f"subpatterns={self.subpatterns}",
                  f"unit_ms={self.unit_ms:g}"]
        defaults = TactileParams()
        for item in fields(self):
            if item.name in (*_COUNTS, "condition", "selection_unit_ms"):
                continue
            value = getattr(self, item.name)
            if value != getattr(defaults, item.name):
                shown.append(f"{item.name}={value!r}")
        if self.selection_unit_ms != self.unit_ms:
            shown.append(f"selection_unit_ms={self.selection_unit_ms:g}")
        text = f"TactileParams({', '.join(shown)})"
        return text if len(text) < 200 else text[:194] + ", …)"

    @property
    def units_per_subpattern(self) -> int:
        """How many consecutive selected units each sub-pattern analyses as one (1 for A–C,
        15 for D–F)."""
        return int(round(self.unit_ms / self.selection_unit_ms))

    @property
    def stretch_ms(self) -> float:
        """Length in ms of the stretch of the recording the pattern is made from."""
        return self.subpatterns * self.unit_ms

    def to_json(self) -> dict:
        """Every field, JSON-ready (recorded in a profile's provenance).

        ``model`` is left out when it is ``"sines"`` (the default): the provenance of every
        profile built before the residual existed, and so the bundled pens' versions, stay as
        they were; reading such a provenance back gives ``"sines"``."""
        data = asdict(self)
        if data["model"] == "sines":
            del data["model"]
        return data

    def updated(self, **options) -> TactileParams:
        """A copy with ``options`` changed, keeping the counts consistent.

        A new ``condition`` brings its own counts (unless they are given too, and then they
        must agree); new counts without a condition leave the old condition behind (the
        pattern is no longer that condition); a new ``unit_ms`` brings its own
        ``selection_unit_ms`` unless that is given.

        Example:
            >>> TactileParams(condition="B", seed=3).updated(condition="E").unit_ms
            1500.0
            >>> TactileParams(condition="B").updated(top=7).condition is None
            True
        """
        unknown = sorted(set(options) - {item.name for item in fields(self)})
        if unknown:
            raise ParameterError(unknown[0], "is not a parameter of the tactile pipeline")
        values = asdict(self)
        if "condition" in options:
            for name in (*_COUNTS, "selection_unit_ms"):
                values[name] = None
        elif any(name in options for name in (*_COUNTS, "selection_unit_ms")):
            values["condition"] = None
        if "unit_ms" in options and "selection_unit_ms" not in options:
            values["selection_unit_ms"] = None
        values.update(options)
        return TactileParams(**values)

    @classmethod
    def for_condition(cls, condition: str, **overrides) -> TactileParams:
        """Parameters of a study condition A–F, with other fields overridden.

        Same as ``TactileParams(condition=condition, **overrides)``.
        """
        return cls(condition=condition, **overrides)

    @classmethod
    def resolve(cls, condition: str | None, top: int | None = None, subpatterns: int | None = None,
                unit_ms: float | None = None, **options) -> TactileParams:
        """A condition preset or explicit counts (unset counts keep B's); counts that disagree
        with the condition are refused. With neither, condition B is recorded."""
        if condition is None and top is None and subpatterns is None and unit_ms is None:
            condition = "B"
        return cls(top=top, subpatterns=subpatterns, unit_ms=unit_ms, condition=condition,
                   **options)
