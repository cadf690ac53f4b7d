"""MPEG-I haptics interchange (ISO/IEC 23090-31) ``.hjif``: the components as sine effects.

Unlike the envelope formats, ``.hjif`` carries the superposition itself: every component of
every sub-pattern becomes a ``Basis`` effect with ``base_signal`` ``"Sine"`` in one
``VectorialWave`` band, positioned where its sub-pattern starts and shaped by amplitude
keyframes that reproduce the crossfades between sub-patterns (linear or equal-power ramps approximated by
five linear keyframes). Summing the effects gives back the tactile pattern.

Every file is valid under MPEG's published JSON schemas (github.com/MPEGGroup/
HapticJSONSchemas, draft-04; ``tests/test_hjif.py`` checks each bundled pen against them), and
the field names follow the MPEG reference software (MPEGGroup/HapticReferenceSoftware):

- top level: ``version`` "2023", ``profile`` "Main", ``level`` 1, ``date`` (an RFC 3339
  date-time, the schema's ``date-time`` format: :func:`creation_date`), ``description``,
  ``timescale`` (ticks per second; Main ≤ 48000), ``avatars``, ``perceptions``, ``syncs``;
- perception: ``id``, ``avatar_id`` (0: unspecified), ``description``,
  ``perception_modality`` "Vibrotactile", ``effect_library``, ``channels`` and one
  ``reference_devices`` entry, the pattern's actuator, with id :data:`REFERENCE_DEVICE_ID` (1:
  the schema's ids start at 1 and the reference software's conformance check rejects 0) and
  its ``type`` (:func:`device_type`);
- channel: ``id``, ``description``, ``gain``, ``mixing_coefficient``, ``body_part_mask``,
  ``reference_device_id``, ``bands`` (level 1: at most 7);
- band: ``band_type`` "VectorialWave", ``lower_frequency_limit`` and
  ``upper_frequency_limit`` (Hz), ``effects``;
- effect: ``effect_type`` "Basis", ``position`` (ticks), ``phase`` (rad, 0 … 6.28318),
  ``base_signal`` "Sine", ``keyframes`` of {``relative_position`` (ticks),
  ``amplitude_modulation``}, the first also carrying ``frequency_modulation`` (whole Hz).

Frequency once per effect, by measurement. The reference renderer advances an effect's phase
between two frequency keyframes as if their positions were milliseconds, whatever the
timescale. A file with the frequency on every keyframe at timescale 8000 therefore plays
wrongly there (correlation 0.45 with RealPen's render); with the frequency on each effect's
first keyframe only, the reference renderer and RealPen's reader
(:mod:`realpen.exports.readers.hjif`) both give the pattern back at 46–49 dB MPEG PSNR
(``benchmarks/hjif_reference_render.py`` runs the reference Synthesizer; docs/exports.md has
the figures).

The timescale is the pattern's rate (8000 ticks/s for bundled pens; at most 48000), so
positions fall on samples. Phases follow RealPen's synthesis, ``a·sin(2πf·t + φ)`` with t from
the effect's position, as the reference renderer plays them.

An effect is taken to sound from its position through its last keyframe (as the reference
renderer plays it); pieces of one component (below) and effects of consecutive hard-bounded
sub-patterns therefore end one tick before the next begins.

What it cannot carry: the residual noise of a ``sines+residual`` pattern (the file holds its
sines; the export says so in its limits); frequencies finer than 1 Hz (``frequency_modulation`` is an integer;
each effect's phase is set so the rounding error is zero at its middle, and a component is
split into pieces where needed to keep the error under 0.05 rad at their ends: the sum comes
back within about 3 % RMS); a loop flag — the file holds ``repeats`` periods, and the first
fade-in and last fade-out (which wrap around the loop) are cut at the file's ends; the sound.
"""

from __future__ import annotations

import datetime as _dt
import json

import numpy as np

from realpen._version import __version__
from realpen.errors import ParameterError, fail
from realpen.exports.base import (
    RESIDUAL_NOT_CARRIED,
    Export,
    check_pattern,
    check_span,
    residual_limits,
    title,
)
from realpen.tactile.pattern import Component, TactilePattern
from realpen.tactile.synthesis import fade_samples, subpattern_samples

__all__ = ["SUFFIX", "MAX_TIMESCALE", "MAX_DRIFT_RAD", "MAX_PHASE", "MAX_EFFECTS", "LIMITS",
           "REFERENCE_DEVICE_ID", "device_type", "creation_date", "effects", "build", "export"]

SUFFIX = ".hjif"
MAX_TIMESCALE = 48000
RAMP = np.linspace(0.0, 1.0, 5)  # keyframes across each crossfade
MAX_DRIFT_RAD = 0.05  # phase error allowed at an effect's ends from whole-Hz frequencies
MAX_PHASE = 6.28318  # the effect schema's maximum phase (rad)
MAX_EFFECTS = 100_000
"""The most sine effects one ``.hjif`` file holds (about 1 kB of JSON each): the method's
pattern needs about 600 per period."""
LIMITS = (
    "frequencies rounded to whole Hz (phases re-set every piece: ≤ 0.05 rad drift)",
    "no loop flag: whole periods; the wrap crossfade is cut at the file's two ends",
    "the sound is not carried",
)


REFERENCE_DEVICE_ID = 1
"""The id of the one reference device (the pattern's actuator): the schema's ids start at 1,
and the reference software's conformance check rejects 0."""
_DEVICE_TYPES = {"lra": "LRA", "vca": "VCA", "voicecoil": "VCA", "voice-coil": "VCA",
                 "erm": "ERM", "piezo": "Piezo"}


def device_type(actuator) -> str:
    """The schema's reference-device ``type`` of an actuator (``LRA``, ``VCA``, ``ERM``,
    ``Piezo``), from the model name of its spec (``lra:f0=175,q=8`` → ``LRA``); ``Unknown``
    for none or another model."""
    if actuator is None:
        return "Unknown"
    model = str(actuator.spec).split(":", 1)[0].strip().lower()
    return _DEVICE_TYPES.get(model, "Unknown")


def creation_date(date: str | None = None) -> str:
    """The file's ``date``: an RFC 3339 date-time, as the schema's ``"format": "date-time"``
    asks.

    Args:
        date: an ISO 8601 date-time (kept, ``Z`` for UTC; a time without a zone is read as
            UTC) or a date (its midnight UTC); None: now, UTC, to the second.

    Raises:
        ParameterError: (parameter ``date``) text that is neither.
    """
    if date is None:
        moment = _dt.datetime.now(_dt.UTC).replace(microsecond=0)
    else:
        try:
            moment = _dt.datetime.fromisoformat(str(date).strip())
        except ValueError:
            raise ParameterError("date", f"must be an ISO 8601 date or date-time, got "
                                         f"{date!r}") from None
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=_dt.UTC)
    text = moment.isoformat()
    return text[:-6] + "Z" if text.endswith("+00:00") else text


def _ramps(start: int, length: int, fade: int, component: Component
           ) -> tuple[np.ndarray, np.ndarray]:
    """Sample times and levels of one component's envelope: fade in, hold, fade out.

    As in the synthesis, a side where the component continues a track fades linearly, any
    other side with the equal-power (sine) ramp.
    """
    amplitude = component.amplitude
    if not fade:
        return np.array([start, start + length], dtype=float), np.array([amplitude, amplitude])
    rise = RAMP if component.joins_previous else np.sin(0.5 * np.pi * RAMP)
    fall = (RAMP if component.joins_next else np.sin(0.5 * np.pi * RAMP))[::-1]
    times = np.concatenate([start - fade // 2 + fade * RAMP,
                            start + length - fade // 2 + fade * RAMP])
    return times, amplitude * np.concatenate([rise, fall])


def _effect(start: int, length: int, fade: int, component: Component, first: int,
            stop: int, rate: int, timescale: int) -> dict:
    """The sine effect of one component of the sub-pattern starting at sample ``start``,
    covering samples ``first`` … ``stop - 1``.

    ``component`` holds frequency (Hz), amplitude (full scale) and phase (rad) at ``start``.
    """
    times, levels = _ramps(start, length, fade, component)
    last = stop - 1
    inside = (times > first) & (times < last)
    t = np.concatenate([[first], times[inside], [last]])
    v = np.interp(t, times, levels)
    ticks, unique = np.unique(np.rint(t * timescale / rate).astype(int), return_index=True)
    v = v[unique]
    frequency = max(1, int(round(component.frequency_hz)))
    # Phase at the effect's position; the whole-Hz rounding error is zero at its middle.
    phase = (component.phase + 2 * np.pi * component.frequency_hz * (first - start) / rate
             + np.pi * (component.frequency_hz - frequency) * (last - first) / rate)
    return {"effect_type": "Basis", "position": int(ticks[0]),
            "phase": _schema_phase(phase), "base_signal": "Sine",
            "keyframes": [{"relative_position": int(k - ticks[0]),
                           "amplitude_modulation": round(float(a), 6),
                           **({"frequency_modulation": frequency} if index == 0 else {})}
                          for index, (k, a) in enumerate(zip(ticks, v))]}


def _schema_phase(phase: float) -> float:
    """``phase`` (rad) in the schema's range 0 … :data:`MAX_PHASE` at 6 decimals; a phase
    that rounds above it is within 5·10⁻⁶ rad of 2π, i.e. of 0."""
    value = round(float(np.mod(phase, 2 * np.pi)), 6)
    return 0.0 if value > MAX_PHASE else value


def _pieces(component: Component, samples: int, rate: int) -> int:
    """Pieces a component's effect over ``samples`` samples is split into, so that its
    whole-Hz frequency drifts at most :data:`MAX_DRIFT_RAD` from its true phase."""
    error_hz = abs(component.frequency_hz - max(1, round(component.frequency_hz)))
    return max(1, int(np.ceil(np.pi * error_hz * samples / rate / MAX_DRIFT_RAD)))


def effects(pattern: TactilePattern, repeats: int = 1, name: str = "pattern"
            ) -> tuple[list[dict], int]:
    """All sine effects of ``repeats`` periods, sorted by position, and the timescale (ticks/s).

    A component whose whole-Hz frequency would drift more than :data:`MAX_DRIFT_RAD` from its
    true phase at either end of its span is split into equal pieces, each with its own phase.

    Raises:
        RealPenError: (naming ``name``) more than :data:`MAX_EFFECTS` effects, counted before
            any is made.
    """
    tactile = check_pattern(pattern)
    rate = tactile.rate
    timescale = min(rate, MAX_TIMESCALE)
    length = subpattern_samples(rate, tactile.subpattern_ms)
    # As the synthesis: even, centred on the boundary, at most one sub-pattern.
    fade = fade_samples(rate, tactile.subpattern_ms, tactile.boundary, tactile.crossfade_ms)
    count = len(tactile.subpatterns)
    end = length * count * repeats
    # Counted over full spans (the file's two ends are shorter): an upper bound.
    needed = repeats * sum(_pieces(component, length + fade, rate)
                           for sub in tactile.subpatterns for component in sub)
    if needed > MAX_EFFECTS:
        raise fail(name, f"a .hjif file of {repeats} period(s) would hold {needed:,} sine "
                         f"effects; the limit is {MAX_EFFECTS:,} (fewer repeats or a shorter "
                         f"pattern)")
    found = []
    for index in range(count * repeats):
        start = index * length
        lo, hi = max(0, start - fade // 2), min(end, start + length + fade - fade // 2)
        for component in tactile.subpatterns[index % count]:
            pieces = _pieces(component, hi - lo, rate)
            bounds = np.round(np.linspace(lo, hi, pieces + 1)).astype(int)
            found += [_effect(start, length, fade, component, int(a), int(b), rate, timescale)
                      for a, b in zip(bounds[:-1], bounds[1:])]
    found.sort(key=lambda effect: effect["position"])
    return found, timescale


def build(pattern: TactilePattern, *, repeats: int = 1, date: str | None = None,
          name: str = "pattern", tool: str = "", version: str | None = None) -> dict:
    """The ``.hjif`` document, as a dict ready for ``json.dumps``.

    Args:
        pattern: the tactile pattern (its actuator, when known, is the reference device).
        repeats: periods of the tactile pattern laid end to end.
        date: ISO 8601 date-time, or a date (read as its midnight UTC); default: now, UTC.
        name, tool, version: for the descriptions (version default: the pattern's).
    """
    pattern = check_pattern(pattern)
    repeats = check_span(pattern, repeats, name)
    found, timescale = effects(pattern, repeats, name)
    frequencies = [effect["keyframes"][0]["frequency_modulation"] for effect in found]
    actuator = pattern.actuator
    device = {"id": REFERENCE_DEVICE_ID,
              "name": actuator.spec if actuator is not None else "unspecified",
              "type": device_type(actuator)}
    if actuator is not None and "f0" in actuator.params:
        device["resonance_frequency"] = float(actuator.params["f0"])
    band = {"band_type": "VectorialWave",
            "lower_frequency_limit": int(min(frequencies)),
            "upper_frequency_limit": int(max(frequencies)),
            "effects": found}
    channel = {"id": 0, "description": f"{name} tactile pattern", "gain": 1.0,
               "mixing_coefficient": 1.0, "body_part_mask": 0,
               "reference_device_id": REFERENCE_DEVICE_ID,
               "bands": [band]}
    perception = {"id": 0, "avatar_id": 0,
                  "description": f"{title(name, tool)}: RealPen tactile pattern",
                  "perception_modality": "Vibrotactile", "reference_devices": [device],
                  "effect_library": [], "channels": [channel]}
    return {"version": "2023", "profile": "Main", "level": 1,
            "date": creation_date(date),
            "description": f"RealPen {__version__}: {name}, {repeats} period(s) of the "
                           f"tactile pattern, version {version or pattern.version}",
            "timescale": timescale, "avatars": [], "perceptions": [perception], "syncs": []}


def export(pattern: TactilePattern, sound=None, coupling=None, *, name: str = "pattern",
           tool: str = "", version: str | None = None, repeats: int = 1,
           date: str | None = None) -> Export:
    """Render the ``.hjif`` file; see the module docstring and :func:`build` for the options.
    ``sound`` and ``coupling`` are not carried."""
    document = build(pattern, repeats=repeats, date=date, name=name, tool=tool,
                     version=version)
    band = document["perceptions"][0]["channels"][0]["bands"][0]
    return Export((json.dumps(document, indent=2, allow_nan=False) + "\n").encode("utf-8"),
                  f"{len(band['effects'])} sine effects, {band['lower_frequency_limit']}–"
                  f"{band['upper_frequency_limit']} Hz, timescale {document['timescale']}/s",
                  limits=LIMITS + residual_limits(pattern, RESIDUAL_NOT_CARRIED))
