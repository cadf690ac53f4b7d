"""Apple Core Haptics AHAP: a continuous event shaped by intensity and sharpness curves.

Layout (keys as in Apple's "Representing haptic patterns in AHAP files" and the CHHapticPattern
key reference):

- ``Version`` 1.0, ``Metadata`` (Project, Created, Description; ignored by the framework);
- ``HapticContinuous`` events with ``HapticIntensity`` 1 and ``HapticSharpness`` 0 spanning
  the pattern (split every 30 s: Lofelt's AHAP converter limits a continuous event to 30 s);
- ``ParameterCurve`` ``HapticIntensityControl`` following the pattern's frame RMS relative to
  its loudest frame (Core Haptics multiplies the event's intensity by it) and
  ``HapticSharpnessControl`` following its spectral centroid mapped log-wise from 30–500 Hz to
  0–1 (Core Haptics adds it to the event's sharpness 0);
- ``AudioCustom`` events playing the friction-sound unit (``EventWaveformPath``, a 16-bit WAV
  written beside the AHAP) back to back, one per unit length — when a sound loop is given
  (``sound_events=True`` asks for them and refuses to go without the sound).

Control-point times are relative to their curve's ``Time`` (Apple: "relative to the start
time of the parameter curve"; Lofelt's converter wrote absolute times, correct only for its
first curve, a bug later fixed in other converters such as haptify). Each curve holds at most
16 control points, consecutive curves sharing their boundary point: Lofelt's converter splits
curves at 16 points; I found no Apple statement of the limit, so this keeps to the safe side.
Pattern entries are sorted by time.

Limits, checked on the finished document before anything is written (:func:`check_limits`),
each refusal one line naming the limit — on the phone, Core Haptics would clamp or drop
silently:

- :data:`MAX_CURVE_POINTS` control points per parameter curve (Lofelt's converter);
- :data:`MAX_EVENT_S` per continuous event (Apple, ``CHHapticEvent.duration``: "The maximum
  duration of a continuous haptic event is 30 seconds");
- :data:`MAX_PATTERN_S` for the whole pattern: Apple publishes no limit and the converters
  (Lofelt's, Meta's haptics SDK) enforce none, so this is the limit of every RealPen export
  (:data:`~realpen.exports.base.MAX_EXPORT_S`, ten minutes: 60 000 control points per
  parameter at one per 10 ms frame);
- :data:`MAX_SOUND_EVENTS` ``AudioCustom`` events (RealPen's bound, also checked before the
  events are made).

What it cannot carry: the superposed components — the engine plays one waveform whose
intensity and sharpness follow the pattern's RMS and centroid; a loop flag — the file holds
``repeats`` periods (loop at playback with ``CHHapticAdvancedPatternPlayer.loopEnabled`` and
``loopEnd`` = the period); a sample-accurate seam between sound units (each unit is its own
event; Apple: custom waveforms "behave like transient events, with no looping"); the coupling
of the feedback to pressure and speed (Eq. 1), which the app applies with dynamic parameters:
with a coupling, the export writes beside the AHAP a Swift player, ``<stem>.swift``
(:func:`realpen.exports.snippets.swift_player`), that loops it and sends
``hapticIntensityControl`` from the pen's pressure and speed.
"""

from __future__ import annotations

import datetime as _dt
import io
import json
import math

import numpy as np

from realpen._version import __version__
from realpen.errors import ParameterError, fail
from realpen.exports import envelope as env
from realpen.exports.base import (
    MAX_EXPORT_S,
    RESIDUAL_IN_ENVELOPE,
    Export,
    check_pattern,
    check_span,
    residual_limits,
    sound_samples,
)
from realpen.exports.snippets import swift_player
from realpen.tactile.pattern import TactilePattern

__all__ = ["SUFFIX", "MAX_CURVE_POINTS", "MAX_EVENT_S", "MAX_PATTERN_S", "MAX_SOUND_EVENTS",
           "LIMITS", "build", "check_limits", "pattern_end", "sound_wav", "export"]

SUFFIX = ".ahap"
MAX_CURVE_POINTS = 16
"""The most control points one ``ParameterCurve`` holds (Lofelt's converter splits at 16)."""
MAX_EVENT_S = 30.0
"""The longest continuous event in s (Apple: "The maximum duration of a continuous haptic
event is 30 seconds")."""
MAX_PATTERN_S = MAX_EXPORT_S
"""The longest pattern in s: no published limit; RealPen's for every export (ten minutes)."""
MAX_SOUND_EVENTS = 10_000
"""The most ``AudioCustom`` events one AHAP holds, one per sound unit: 2000 units of the
method's 300 ms fill the longest export (:data:`~realpen.exports.base.MAX_EXPORT_S`)."""
LIMITS = (
    "one waveform at a time: intensity follows the frame RMS, sharpness the spectral centroid",
    "no loop flag: loop with CHHapticAdvancedPatternPlayer.loopEnabled, loopEnd = period",
    "sound units are separate AudioCustom events: the seams are only as exact as the "
    "engine's scheduling",
)
NO_SOUND = "no sound was given: the AHAP holds no AudioCustom events"


def _curves(parameter: str, times: np.ndarray, values: np.ndarray) -> list[dict]:
    curves = []
    start = 0
    while start < len(times) - 1:
        stop = min(start + MAX_CURVE_POINTS - 1, len(times) - 1)
        origin = float(times[start])
        curves.append({"ParameterCurve": {
            "ParameterID": parameter,
            "Time": round(origin, 6),
            "ParameterCurveControlPoints": [
                {"Time": round(float(t) - origin, 6), "ParameterValue": round(float(v), 4)}
                for t, v in zip(times[start:stop + 1], values[start:stop + 1])]}})
        start = stop
    return curves


def _continuous(total_s: float) -> list[dict]:
    events = []
    for index in range(math.ceil(total_s / MAX_EVENT_S - 1e-9)):
        start = index * MAX_EVENT_S
        events.append({"Event": {
            "Time": start, "EventType": "HapticContinuous",
            "EventDuration": round(min(MAX_EVENT_S, total_s - start), 6),
            "EventParameters": [{"ParameterID": "HapticIntensity", "ParameterValue": 1.0},
                                {"ParameterID": "HapticSharpness", "ParameterValue": 0.0}]}})
    return events


def _sounds(unit_s: float, total_s: float, path: str) -> list[dict]:
    count = math.ceil(total_s / unit_s - 1e-9)
    return [{"Event": {"Time": round(index * unit_s, 6), "EventType": "AudioCustom",
                       "EventWaveformPath": path,
                       "EventParameters": [{"ParameterID": "AudioVolume", "ParameterValue": 1.0}]}}
            for index in range(count)]


def _wants_sound(sound, sound_events: bool | None) -> bool:
    if sound_events and sound is None:
        raise ParameterError("sound", "AHAP sound events (AudioCustom) need the sound: give a "
                                      "sound loop (sound=...), or sound_events=False")
    return sound is not None if sound_events is None else bool(sound_events)


def build(pattern: TactilePattern, sound=None, *, repeats: int = 1,
          sound_events: bool | None = None, sound_file: str | None = None,
          created: str | None = None, name: str = "pattern", tool: str = "",
          version: str | None = None) -> dict:
    """The AHAP document, as a dict ready for ``json.dumps``.

    Args:
        pattern: the tactile pattern.
        sound: the sound loop (``samples``, ``rate`` in Hz), played as ``AudioCustom`` events.
        repeats: periods of the tactile pattern laid end to end.
        sound_events: add the sound as ``AudioCustom`` events (None: when ``sound`` is given;
            True without a sound is refused).
        sound_file: the ``EventWaveformPath`` (default ``<name>-sound.wav``).
        created: the ``Metadata.Created`` date (default: today, ISO 8601).
        name, tool, version: for ``Metadata`` (version default: the pattern's).

    Raises:
        ParameterError: ``sound_events=True`` without a sound, or a bad ``repeats``.
        RealPenError: a limit of :func:`check_limits` broken.
    """
    pattern = check_pattern(pattern)
    repeats = check_span(pattern, repeats, name)
    with_sound = _wants_sound(sound, sound_events)
    measured = env.measure(pattern.samples, pattern.rate, source=name)
    times, intensity = env.loop_curve(measured, measured.intensity, repeats)
    _, sharp = env.loop_curve(measured, env.sharpness(measured.centroid_hz), repeats)
    total = measured.period_s * repeats
    entries = _continuous(total)
    entries += _curves("HapticIntensityControl", times, intensity)
    entries += _curves("HapticSharpnessControl", times, sharp)
    if with_sound:
        loop, rate = sound_samples(sound, "AHAP sound events")
        if total * rate / len(loop) > MAX_SOUND_EVENTS:
            raise fail(name, f"the sound loop ({len(loop) / rate * 1000:g} ms) would need more "
                             f"than {MAX_SOUND_EVENTS:,} AudioCustom events over "
                             f"{total:g} s")
        entries += _sounds(len(loop) / rate, total, sound_file or f"{name}-sound.wav")
    entries.sort(key=lambda entry: next(iter(entry.values()))["Time"])
    what = f"{tool}: " if tool else ""
    return check_limits({
        "Version": 1.0,
        "Metadata": {"Project": f"RealPen {name}",
                     "Created": created or _dt.date.today().isoformat(),
                     "Description": f"{what}{total * 1000:g} ms "
                                    f"({repeats} × {measured.period_s * 1000:g} ms), RealPen "
                                    f"{__version__}, version {version or pattern.version}"},
        "Pattern": entries,
    }, name)


def pattern_end(document: dict) -> float:
    """Where an AHAP document's pattern ends, in s: the latest end of a continuous event, of a
    parameter curve's last control point, or the start of any other event."""
    end = 0.0
    for entry in document["Pattern"]:
        if "Event" in entry:
            event = entry["Event"]
            end = max(end, event["Time"] + event.get("EventDuration", 0.0))
        elif "ParameterCurve" in entry:
            curve = entry["ParameterCurve"]
            points = curve["ParameterCurveControlPoints"]
            end = max(end, curve["Time"] + (points[-1]["Time"] if points else 0.0))
    return end


def check_limits(document: dict, name: str = "pattern") -> dict:
    """``document`` if it keeps the AHAP limits of the module docstring.

    Args:
        document: an AHAP document (as :func:`build` makes it).
        name: names the pen in an error.

    Raises:
        RealPenError: one line naming the limit broken and where: a parameter curve of more
            than :data:`MAX_CURVE_POINTS` control points, a continuous event longer than
            :data:`MAX_EVENT_S`, a pattern longer than :data:`MAX_PATTERN_S`, or more than
            :data:`MAX_SOUND_EVENTS` ``AudioCustom`` events.
    """
    audio = 0
    for entry in document["Pattern"]:
        curve = entry.get("ParameterCurve")
        if curve is not None and len(curve["ParameterCurveControlPoints"]) > MAX_CURVE_POINTS:
            raise fail(name, f"the {curve['ParameterID']} curve at {curve['Time']:g} s holds "
                             f"{len(curve['ParameterCurveControlPoints'])} control points; an "
                             f"AHAP parameter curve holds at most {MAX_CURVE_POINTS}")
        event = entry.get("Event", {})
        if event.get("EventType") == "HapticContinuous" \
                and event["EventDuration"] > MAX_EVENT_S + 1e-9:
            raise fail(name, f"the continuous event at {event['Time']:g} s lasts "
                             f"{event['EventDuration']:g} s; Core Haptics plays a continuous "
                             f"event for at most {MAX_EVENT_S:g} s")
        audio += event.get("EventType") == "AudioCustom"
    end = pattern_end(document)
    if end > MAX_PATTERN_S + 1e-9:
        raise fail(name, f"the AHAP pattern lasts {end:g} s; an AHAP export holds at most "
                         f"{MAX_PATTERN_S:g} s")
    if audio > MAX_SOUND_EVENTS:
        raise fail(name, f"the AHAP holds {audio:,} AudioCustom events; the limit is "
                         f"{MAX_SOUND_EVENTS:,}")
    return document


def sound_wav(sound) -> bytes:
    """The sound loop as a 16-bit PCM WAV at its own rate (a format every audio API reads)."""
    import soundfile as sf

    loop, rate = sound_samples(sound, "the AHAP's sound file")
    buffer = io.BytesIO()
    sf.write(buffer, np.clip(loop, -1.0, 1.0), rate, subtype="PCM_16", format="WAV")
    return buffer.getvalue()


def export(pattern: TactilePattern, sound=None, coupling=None, *, name: str = "pattern",
           tool: str = "", version: str | None = None, repeats: int = 1,
           sound_events: bool | None = None, sound_file: str | None = None,
           created: str | None = None, ahap_file: str | None = None) -> Export:
    """Render the AHAP, the sound WAV it refers to, and, when ``coupling`` is given, the Swift
    player (:func:`realpen.exports.snippets.swift_player`) that loops it with its intensity
    following Eq. 1; see the module docstring and :func:`build` for the options.

    Args:
        ahap_file: the AHAP's file name, which the Swift player loads (default
            ``<name>.ahap``); the player is written as ``<its stem>.swift``.
    """
    file_name = sound_file or f"{name}-sound.wav"
    document = build(pattern, sound, repeats=repeats, sound_events=sound_events,
                     sound_file=file_name, created=created, name=name, tool=tool,
                     version=version)
    curves = sum("ParameterCurve" in entry for entry in document["Pattern"])
    audio = sum(entry.get("Event", {}).get("EventType") == "AudioCustom"
                for entry in document["Pattern"])
    total = sum(entry["Event"]["EventDuration"] for entry in document["Pattern"]
                if entry.get("Event", {}).get("EventType") == "HapticContinuous")
    summary = (f"{total * 1000:g} ms continuous event, {curves} parameter curves"
               + (f", {audio} AudioCustom events playing {file_name}" if audio else ""))
    limits = (LIMITS if audio else (*LIMITS[:2], NO_SOUND)) \
        + residual_limits(pattern, RESIDUAL_IN_ENVELOPE)
    companions = {file_name: sound_wav(sound)} if audio else {}
    if coupling is not None:
        ahap_name = ahap_file or f"{name}{SUFFIX}"
        period = pattern.frames / pattern.rate
        source = swift_player(name, coupling, period, ahap_name)
        companions[f"{ahap_name.rpartition('.')[0] or ahap_name}.swift"] = source.encode("utf-8")
        summary += ", a Swift player applying Eq. 1"
    return Export((json.dumps(document, indent=2, allow_nan=False) + "\n").encode("utf-8"),
                  summary, companions, limits)
