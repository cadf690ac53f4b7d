"""The tactile pattern of a study trial: a pen's own, or rebuilt from its source with a
condition's parameters (study 1's A–F are the ballpoint's source under six parameter sets).

A pen's source is what its profile was built from. For the bundled pens that is the RealPen pen
model, which is deterministic: the profile's provenance names the model's pen, paper and seed,
and the vibration is generated again, the same to the last sample. The pattern is then built
with the profile's own tactile parameters and actuator, the trial's counts replacing the
profile's (``top``, ``subpatterns``, ``unit_ms``, or a paper condition ``A``–``F``), so the
conditions differ in nothing else.
"""

from __future__ import annotations

import threading

from realpen.errors import RealPenError
from realpen.profile.bundle import PenProfile
from realpen.tactile.pattern import TactilePattern, canonical_json

__all__ = ["COUNT_FIELDS", "source_recording", "condition_pattern", "PatternCache"]

COUNT_FIELDS = ("top", "subpatterns", "unit_ms", "condition", "selection_unit_ms")
"""The profile parameters a trial's ``tactile`` replaces (the rest are the profile's own)."""


def source_recording(profile: PenProfile):
    """The vibration recording a profile was built from, generated again from its model.

    Raises:
        RealPenError: the profile was built from a recording RealPen does not keep (only
            modelled pens can be rebuilt; build the conditions' profiles yourself and name them
            as the trials' pens instead).
    """
    from realpen.pens.model import PENS, PaperModel, vibration

    model = profile.meta.provenance.model
    pen = PENS.get((model or {}).get("pen", {}).get("name", ""))
    if model is None or pen is None or pen.to_json() != model.get("pen"):
        raise RealPenError(f"{profile.name}: the profile was built from a recording RealPen does "
                           f"not keep, so its tactile pattern cannot be rebuilt with other "
                           f"parameters; build one profile per condition and name it as the pen")
    try:
        paper = PaperModel(**model.get("paper", {}))
        return vibration(pen, paper, seed=int(model["seed"]))
    except (KeyError, TypeError, ValueError) as error:
        raise RealPenError(f"{profile.name}: the profile's pen model cannot be rebuilt "
                           f"({error})") from None


def condition_pattern(profile: PenProfile, tactile: dict) -> TactilePattern:
    """The profile's tactile pattern rebuilt from its source with a condition's counts, as the
    method builds it (sines only, even for a profile built with the residual).

    Args:
        profile: the pen (its source, actuator and tactile parameters are used).
        tactile: :class:`~realpen.tactile.conditions.TactileParams` keywords replacing the
            profile's counts: ``condition`` (``A``–``F``) and/or ``top``, ``subpatterns``,
            ``unit_ms`` (ms).

    Raises:
        RealPenError: the profile cannot be rebuilt (see :func:`source_recording`), or the
            parameters are refused (a ``ParameterError`` naming the parameter).
    """
    # imported here: the analysis (scipy.signal) is loaded when a condition is first built,
    # not when the server starts
    from realpen.tactile.build import build_pattern

    # The conditions are the method's stimuli: sines only, whatever model the profile uses.
    base = {name: value for name, value in profile.meta.provenance.tactile_parameters.items()
            if name not in (*COUNT_FIELDS, "model")}
    return build_pattern(source_recording(profile), profile.actuator, None, None,
                         **{**base, **tactile})


class PatternCache:
    """Built condition patterns, by profile version and parameters (thread-safe; building one
    takes tens of milliseconds, serving it again nothing)."""

    def __init__(self) -> None:
        self._patterns: dict[tuple[str, bytes], TactilePattern] = {}
        self._lock = threading.Lock()

    def get(self, profile: PenProfile, tactile: dict) -> TactilePattern:
        """:func:`condition_pattern`, built once per (profile version, parameters)."""
        key = (profile.version, canonical_json(tactile))
        with self._lock:
            pattern = self._patterns.get(key)
            if pattern is None:
                pattern = self._patterns[key] = condition_pattern(profile, tactile)
        return pattern
