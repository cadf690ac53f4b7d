"""Read an Apple Core Haptics AHAP file and render what Core Haptics would play.

Semantics from Apple's "Representing haptic patterns in AHAP files" and the Core Haptics
reference (``CHHapticDynamicParameter``, ``CHHapticParameterCurve``):

- ``Pattern`` is a list of entries, each an ``Event``, a ``Parameter`` or a ``ParameterCurve``
  (an entry with none of them is refused: Core Haptics would ignore it silently).
- ``HapticContinuous`` events play from ``Time`` for ``EventDuration`` s; ``HapticTransient``
  events are clicks at ``Time``. Every event needs its ``EventType`` and ``Time`` (and a
  continuous one its ``EventDuration``): a file without them is refused, not defaulted. A
  continuous event lasts at most 30 s (Apple's limit, :data:`realpen.exports.ahap.MAX_EVENT_S`):
  a longer one is cut there, and the notes say so; times beyond
  :data:`~realpen.exports.readers.fields.MAX_PLAY_S` are refused.
  ``HapticIntensity`` and ``HapticSharpness`` are 0 … 1 (read as 1 and 0.5 when absent:
  RealPen's assumption, as Core Haptics' defaults are not stated in the format's
  description) and, like Core Haptics, clamped into range.
- ``HapticIntensityControl`` multiplies every event's intensity, ``HapticSharpnessControl``
  (−1 … 1) adds to its sharpness; the results are clipped to 0 … 1. A ``ParameterCurve``'s
  control-point times are relative to its ``Time`` (Apple: "relative to the start time of the
  parameter curve"); values are linear between points and held after the last one until the
  next curve or ``Parameter`` of the same parameter; a ``Parameter`` sets its value from its
  ``Time`` on. Controls apply to transients too (Apple: curves "apply to all events in a
  pattern").
- Files from Lofelt's converter wrote control-point times as absolute times: when every curve
  starting after 0 has its first point at its own ``Time``, the file's points are read as
  absolute, and the notes say so.
- ``AudioCustom`` and ``AudioContinuous`` events are sound, not vibration: counted in the
  summary, not rendered. ``AttackTime``, ``DecayTime``, ``ReleaseTime`` and ``Sustained`` and
  the other dynamic parameters are not modelled (the notes list them when present).
- The file lasts until the end of its last haptic event.

The vibration is the shared carrier of :mod:`realpen.exports.readers.carrier`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from realpen.exports.ahap import MAX_EVENT_S
from realpen.exports.readers import carrier
from realpen.exports.readers.fields import (
    Playback,
    array,
    check_parts,
    member,
    number,
    problem,
    seconds,
    text,
    where,
)

__all__ = ["EVENT_TYPES", "DEFAULT_INTENSITY", "DEFAULT_SHARPNESS", "read"]

EVENT_TYPES = ("HapticTransient", "HapticContinuous", "AudioContinuous", "AudioCustom")
DEFAULT_INTENSITY = 1.0
DEFAULT_SHARPNESS = 0.5
_CONTROLS = {"HapticIntensityControl": "intensity", "HapticSharpnessControl": "sharpness"}
_ENTRY_KINDS = ("Event", "Parameter", "ParameterCurve")
_UNMODELLED_EVENT = ("AttackTime", "DecayTime", "ReleaseTime", "Sustained")


class _Reading:
    """What has been read so far, and what the notes must say."""

    def __init__(self, source: Path):
        self.source = source
        self.pattern = carrier.Pattern()
        self.audio = 0
        self.curves = 0
        self.parameters = 0
        self.clamped: set[str] = set()
        self.unmodelled: set[str] = set()
        self.curve_entries: list[tuple[str, float, list[tuple[float, float]]]] = []

    def clamp(self, value: float, low: float, high: float, name: str) -> float:
        if not low <= value <= high:
            self.clamped.add(name)
        return min(high, max(low, value))


def _event(reading: _Reading, raw: object, at: str) -> None:
    source = reading.source
    kind = text(member(raw, "EventType", source, at), source, where(at, "EventType"),
                choices=EVENT_TYPES)
    time = seconds(member(raw, "Time", source, at), source, where(at, "Time"))
    if kind.startswith("Audio"):
        reading.audio += 1
        return
    duration = 0.0
    if kind == "HapticContinuous":
        duration = reading.clamp(number(member(raw, "EventDuration", source, at), source,
                                        where(at, "EventDuration"), low=0.0),
                                 0.0, MAX_EVENT_S, "EventDuration")
    values = {"HapticIntensity": DEFAULT_INTENSITY, "HapticSharpness": DEFAULT_SHARPNESS}
    listed = array(member(raw, "EventParameters", source, at, required=False, default=[]),
                   source, where(at, "EventParameters"))
    for index, parameter in enumerate(listed):
        here = where(where(at, "EventParameters"), index)
        name = text(member(parameter, "ParameterID", source, here), source,
                    where(here, "ParameterID"))
        value = member(parameter, "ParameterValue", source, here)
        if name in values:
            values[name] = reading.clamp(number(value, source, where(here, "ParameterValue")),
                                         0.0, 1.0, name)
        elif name in _UNMODELLED_EVENT:
            reading.unmodelled.add(name)
    intensity, sharpness = values["HapticIntensity"], values["HapticSharpness"]
    if kind == "HapticContinuous":
        reading.pattern.continuous.append((time, duration, intensity, sharpness))
    else:
        reading.pattern.transients.append((time, intensity, sharpness))


def _parameter(reading: _Reading, raw: object, at: str) -> None:
    source = reading.source
    name = text(member(raw, "ParameterID", source, at), source, where(at, "ParameterID"))
    time = seconds(member(raw, "Time", source, at), source, where(at, "Time"))
    value = number(member(raw, "ParameterValue", source, at), source,
                   where(at, "ParameterValue"))
    reading.parameters += 1
    if name not in _CONTROLS:
        reading.unmodelled.add(name)
        return
    control = getattr(reading.pattern, _CONTROLS[name])
    control.add(time, [time], [reading.clamp(value, control.low, control.high, name)])


def _curve(reading: _Reading, raw: object, at: str) -> None:
    source = reading.source
    name = text(member(raw, "ParameterID", source, at), source, where(at, "ParameterID"))
    time = seconds(member(raw, "Time", source, at), source, where(at, "Time"))
    points_at = where(at, "ParameterCurveControlPoints")
    points = array(member(raw, "ParameterCurveControlPoints", source, at), source, points_at,
                   min_items=1)
    read_points: list[tuple[float, float]] = []
    for index, point in enumerate(points):
        here = where(points_at, index)
        when = seconds(member(point, "Time", source, here), source, where(here, "Time"))
        if read_points and when < read_points[-1][0]:
            raise problem(source, where(here, "Time"),
                          f"control points must be in time order ({when:g} after "
                          f"{read_points[-1][0]:g})")
        read_points.append((when, number(member(point, "ParameterValue", source, here),
                                         source, where(here, "ParameterValue"))))
    reading.curves += 1
    if name not in _CONTROLS:
        reading.unmodelled.add(name)
        return
    reading.curve_entries.append((name, time, read_points))


def _absolute_points(curves: list[tuple[str, float, list[tuple[float, float]]]]) -> bool:
    """Whether the file writes control-point times as absolute times (Lofelt's converter)."""
    later = [(time, points) for _, time, points in curves if time > 0]
    return bool(later) and all(abs(points[0][0] - time) <= 1e-6 for time, points in later)


def read(document: dict, source: Path) -> Playback:
    """Read a parsed AHAP document.

    Args:
        document: the file's JSON.
        source: the file, for messages.

    Raises:
        RealPenError: one line naming the file and the entry that breaks the format.
    """
    if "Version" in document:
        number(document["Version"], source, "Version", low=0.0)
    entries = array(member(document, "Pattern", source, ""), source, "Pattern", min_items=1)
    check_parts(len(entries), "pattern entries", source)
    reading = _Reading(source)
    readers = {"Event": _event, "Parameter": _parameter, "ParameterCurve": _curve}
    for index, entry in enumerate(entries):
        at = where("Pattern", index)
        if not isinstance(entry, dict):
            raise problem(source, at, "must be an object")
        kinds = [kind for kind in _ENTRY_KINDS if kind in entry]
        if len(kinds) != 1:
            raise problem(source, at, "must hold one Event, Parameter or ParameterCurve, got "
                                      + (", ".join(kinds) or ", ".join(map(str, entry)) or
                                         "nothing"))
        readers[kinds[0]](reading, entry[kinds[0]], where(at, kinds[0]))
    absolute = _absolute_points(reading.curve_entries)
    for name, time, points in reading.curve_entries:
        control = getattr(reading.pattern, _CONTROLS[name])
        times = [when if absolute else time + when for when, _ in points]
        values = [reading.clamp(value, control.low, control.high, name) for _, value in points]
        control.add(time, times, values)

    pattern = reading.pattern
    notes = [carrier.CARRIER_NOTE]
    if pattern.transients:
        notes.append(carrier.TRANSIENT_NOTE)
    if absolute:
        notes.append("control-point times read as absolute times (every curve after 0 starts "
                     "on its own Time, as Lofelt's converter wrote them)")
    if reading.audio:
        notes.append(f"{reading.audio} audio event(s) are sound, not vibration: not rendered")
    if reading.clamped:
        notes.append(f"out-of-range {', '.join(sorted(reading.clamped))} clamped into range, "
                     f"as Core Haptics does")
    if reading.unmodelled:
        notes.append(f"not modelled: {', '.join(sorted(reading.unmodelled))}")
    summary = (f"{len(pattern.continuous)} continuous and {len(pattern.transients)} transient "
               f"haptic events, {reading.curves} parameter curves, {reading.parameters} "
               f"parameters, {reading.audio} audio events, {pattern.duration_s * 1000:g} ms")

    def render(rate: int) -> np.ndarray:
        return pattern.render(rate)

    return Playback(pattern.duration_s, summary, render, tuple(notes))
