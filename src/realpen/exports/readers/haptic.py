"""Read a Lofelt / Meta ``.haptic`` file (data model v1) and render what an iPhone plays of it.

The file is first checked against Lofelt's v1 rules (:func:`realpen.exports.haptic_rules.
check_haptic`). The format leaves the player its waveform; this reader plays the AHAP that
Lofelt's converter makes of the file for iOS (``core/datamodel/src/ios/v1.rs`` of
Lofelt/NiceVibrations; Haptics Studio's iOS export) as Core Haptics plays it, with the shared
carrier (:mod:`realpen.exports.readers.carrier`), so a ``.haptic`` file and its converted
``.ahap`` read to the same vibration:

- one ``HapticContinuous`` event of intensity 1 and sharpness 0 per 30 s from 0 to the last
  amplitude breakpoint;
- an intensity control through every amplitude breakpoint, ``√amplitude`` (times 0.8 at a
  breakpoint with emphasis: Lofelt ducks the continuous signal there), linear in between,
  starting at the first breakpoint;
- a sharpness control through every frequency breakpoint, ``√frequency``, likewise;
- a ``HapticTransient`` at each breakpoint with emphasis, of intensity ``√emphasis amplitude``
  and sharpness ``emphasis frequency`` (not its square root), except at the first breakpoint,
  which the converter skips. As in any AHAP, the intensity control scales the transients too
  (Lofelt's own iOS player splits them into a pattern of their own, unscaled; not modelled).

An envelope of one breakpoint makes no control (Lofelt's converter needs two), so a
one-breakpoint file plays nothing and a one-point frequency envelope leaves the sharpness at 0.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from realpen.exports.ahap import MAX_EVENT_S  # Lofelt's converter splits events there too
from realpen.exports.haptic_rules import check_haptic
from realpen.exports.readers import carrier
from realpen.exports.readers.fields import Playback, check_parts, seconds

__all__ = ["EMPHASIS_DUCKING", "NOTES", "to_pattern", "read"]

EMPHASIS_DUCKING = 0.2  # Lofelt lowers the continuous intensity by this fraction at an emphasis
NOTES = (
    "played as Core Haptics plays the AHAP Lofelt's converter makes of it: intensity "
    "√amplitude (×0.8 at an emphasis), sharpness √frequency, and a transient (intensity "
    "√amplitude, sharpness frequency) for each emphasis after the first breakpoint",
    carrier.CARRIER_NOTE,
)


def to_pattern(document: dict) -> carrier.Pattern:
    """The Core Haptics events Lofelt's converter makes of a checked v1 document."""
    envelopes = document["signals"]["continuous"]["envelopes"]
    amplitude = envelopes["amplitude"]
    pattern = carrier.Pattern()
    end = float(amplitude[-1]["time"])
    for index in range(math.ceil(end / MAX_EVENT_S)):
        start = index * MAX_EVENT_S
        pattern.continuous.append((start, min(MAX_EVENT_S, end - start), 1.0, 0.0))
    if len(amplitude) > 1:
        levels = [math.sqrt(point["amplitude"])
                  * (1.0 - EMPHASIS_DUCKING if point.get("emphasis") is not None else 1.0)
                  for point in amplitude]
        times = [float(point["time"]) for point in amplitude]
        pattern.intensity.add(times[0], times, levels)
    frequency = envelopes.get("frequency") or []
    if len(frequency) > 1:
        times = [float(point["time"]) for point in frequency]
        pattern.sharpness.add(times[0], times, [math.sqrt(p["frequency"]) for p in frequency])
    for point in amplitude[1:]:
        emphasis = point.get("emphasis")
        if emphasis is not None:
            pattern.transients.append((float(point["time"]), math.sqrt(emphasis["amplitude"]),
                                       float(emphasis["frequency"])))
    return pattern


def read(document: dict, source: Path) -> Playback:
    """Read a parsed ``.haptic`` document.

    Args:
        document: the file's JSON.
        source: the file, for messages.

    Raises:
        RealPenError: one line naming the file, the field and the Lofelt v1 rule it breaks.
    """
    check_haptic(document, source)
    envelopes = document["signals"]["continuous"]["envelopes"]
    for name in ("amplitude", "frequency"):
        points = envelopes.get(name) or []
        check_parts(len(points), f"{name} breakpoints", source)
        if points:
            seconds(points[-1]["time"], source, f"signals.continuous.envelopes.{name}"
                                                f"[{len(points) - 1}].time")
    pattern = to_pattern(document)
    envelopes = document["signals"]["continuous"]["envelopes"]
    amplitude = envelopes["amplitude"]
    frequency = envelopes.get("frequency") or []
    version = document["version"]
    emphases = sum(point.get("emphasis") is not None for point in amplitude)
    summary = (f"Lofelt v{version['major']}.{version.get('minor', 0)}.{version.get('patch', 0)}: "
               f"{len(amplitude)} amplitude and {len(frequency)} frequency breakpoints, "
               f"{emphases} emphasis, {pattern.duration_s * 1000:g} ms")
    notes = NOTES + ((carrier.TRANSIENT_NOTE,) if pattern.transients else ())
    if amplitude[0].get("emphasis") is not None:
        notes += ("the first breakpoint's emphasis is not played (Lofelt's converter skips it)",)

    def render(rate: int) -> np.ndarray:
        return pattern.render(rate)

    return Playback(pattern.duration_s, summary, render, notes)
