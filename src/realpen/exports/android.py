"""Android ``VibrationEffect``: waveform steps and envelopes, as JSON with a Kotlin snippet.

Three forms, from the Android reference (developer.android.com, ``VibrationEffect`` and its
nested builders, ``VibratorEnvelopeEffectInfo``):

- ``createWaveform(long[] timings, int[] amplitudes, int repeat)`` (API 26): one step per
  envelope frame (10 ms), amplitude 0 … 255 following the frame RMS relative to the loudest
  frame; ``repeat`` = 0 loops from the first step until ``cancel()`` — the only form here that
  loops seamlessly;
- ``WaveformEnvelopeBuilder`` (API 36): ``addControlPoint(amplitude 0–1, frequencyHz,
  durationMillis)``, the frequency being the pattern's spectral centroid, after
  ``setInitialFrequencyHz``;
- ``BasicEnvelopeBuilder`` (API 36): ``addControlPoint(intensity 0–1, sharpness 0–1,
  durationMillis)``, sharpness from the centroid (log 30–500 Hz → 0–1), after
  ``setInitialSharpness``; it "must end with a zero intensity control point".

Envelope builders start every effect at amplitude 0, and devices guarantee only 16 control
points, control-point durations from 20 ms and up to 1 s (``VibratorEnvelopeEffectInfo``). So
the envelopes use 14 segments per period (each ≥ 20 ms): a first point reached from 0 at the
first segment's centre, one per further segment, one at the period's end holding the wrap value
and a final 20 ms ramp to 0 — 16 points for one period. More ``repeats`` need more points than
every device takes; the JSON says how many.

What it cannot carry: the superposed components (one amplitude and one frequency at a time);
in the envelope forms, a seamless loop — each repetition (e.g. via
``VibrationEffect.createRepeatingEffect``, API 36) restarts from amplitude 0; frequencies the
device cannot play (the framework drops effects outside ``Vibrator.getFrequencyProfile()``'s
range rather than correcting them); the sound.
"""

from __future__ import annotations

import json
import re

import numpy as np

from realpen._version import __version__
from realpen.exports import envelope as env
from realpen.exports.base import RESIDUAL_IN_ENVELOPE, Export, check_pattern, check_span, residual_limits
from realpen.tactile.pattern import TactilePattern

__all__ = ["SUFFIX", "KOTLIN_SUFFIX", "ENVELOPE_SEGMENTS", "MIN_POINT_MS", "GUARANTEED_POINTS",
           "LIMITS", "waveform", "envelopes", "kotlin", "build", "export"]

SUFFIX = ".json"
KOTLIN_SUFFIX = ".kt"
ENVELOPE_SEGMENTS = 14  # + wrap point + final zero = 16, the guaranteed maximum
MIN_POINT_MS = 20  # shortest control-point duration every envelope-capable device takes
GUARANTEED_POINTS = 16
LIMITS = (
    "one amplitude and one frequency at a time: the RMS envelope and the spectral centroid",
    "only the createWaveform form loops seamlessly; envelope forms restart from amplitude 0",
    "the sound is not carried",
)


def waveform(measured: env.Envelope, repeats: int = 1) -> dict:
    """``createWaveform`` arrays of a measured pattern: one step per frame, ``repeats`` periods.

    Returns:
        ``timings_ms`` (ints), ``amplitudes`` (ints 0 … 255, the frame RMS relative to the
        loudest frame) and ``repeat`` 0 (loop from the first step).
    """
    edges_ms = np.round(measured.edges_s * 1000).astype(int)
    timings = np.tile(np.diff(edges_ms), repeats)
    amplitudes = np.tile(np.clip(np.rint(255 * measured.intensity), 0, 255).astype(int), repeats)
    return {"api_level": 26, "timings_ms": timings.tolist(), "amplitudes": amplitudes.tolist(),
            "repeat": 0}


def _envelope_points(measured: env.Envelope, repeats: int
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Durations (ms), relative intensities and centroids (Hz) of the envelope control points."""
    period_ms = measured.period_s * 1000
    count = int(min(ENVELOPE_SEGMENTS, max(1, period_ms // (2 * MIN_POINT_MS))))
    coarse = measured.segments(count)
    level = coarse.rms / float(measured.rms.max())
    times, intensity = env.loop_curve(coarse, level, repeats)
    _, centroid = env.loop_curve(coarse, coarse.centroid_hz, repeats)
    # loop_curve starts at t = 0 on the wrap value; the builders start at 0 by themselves.
    times, intensity, centroid = times[1:], intensity[1:], centroid[1:]
    stamps = np.round(np.append(times * 1000, times[-1] * 1000 + MIN_POINT_MS)).astype(int)
    durations = np.diff(np.concatenate([[0], stamps]))
    return durations, np.append(intensity, 0.0), np.append(centroid, centroid[-1])


def envelopes(measured: env.Envelope, repeats: int = 1) -> tuple[dict, dict]:
    """The ``WaveformEnvelopeBuilder`` and ``BasicEnvelopeBuilder`` control points.

    Amplitude and intensity are 0 … 1 relative to the loudest frame, frequencies in Hz (the
    spectral centroid), sharpness 0 … 1, durations in whole ms.
    """
    durations, intensity, centroid = _envelope_points(measured, repeats)
    sharp = env.sharpness(centroid)
    waveform_env = {
        "api_level": 36, "initial_frequency_hz": round(float(centroid[0]), 2),
        "control_points": [{"amplitude": round(float(a), 4), "frequency_hz": round(float(f), 2),
                            "duration_ms": int(d)}
                           for a, f, d in zip(intensity, centroid, durations)]}
    basic_env = {
        "api_level": 36, "initial_sharpness": round(float(sharp[0]), 4),
        "control_points": [{"intensity": round(float(a), 4), "sharpness": round(float(s), 4),
                            "duration_ms": int(d)}
                           for a, s, d in zip(intensity, sharp, durations)]}
    return waveform_env, basic_env


def kotlin(document: dict) -> str:
    """A short Kotlin object holding the three effects of an Android export document."""
    name = document["name"]
    obj = "".join(part.capitalize() for part in re.split(r"[^A-Za-z0-9]+", name) if part)
    obj = ("Pen" + obj if obj[:1].isdigit() else obj) + "Vibration"
    wave = document["waveform"]
    wenv, benv = document["waveform_envelope"], document["basic_envelope"]

    def points(entries: list[dict], first: str, second: str) -> str:
        return "".join(f"\n        .addControlPoint({p[first]}f, {p[second]}f, {p['duration_ms']}L)"
                       for p in entries)

    def wrapped(values: list[int], suffix: str = "") -> str:
        items = [f"{v}{suffix}" for v in values]
        return ",\n        ".join(", ".join(items[i:i + 15]) for i in range(0, len(items), 15))

    wave_points = points(wenv["control_points"], "amplitude", "frequency_hz")
    basic_points = points(benv["control_points"], "intensity", "sharpness")
    period = document["period_ms"]
    tool = " ".join(document["tool"].split())  # one comment line
    label = f"'{name}' ({tool})" if tool else f"'{name}'"
    return f"""// RealPen {label}: {period:g} ms tactile pattern.
// Generated by RealPen {__version__}; do not edit. Play waveform() while the pen moves on the
// surface and call vibrator.cancel() when it lifts.
import android.os.VibrationEffect

object {obj} {{
    /** Step durations in ms; with AMPLITUDES, one period of the pattern. */
    val TIMINGS = longArrayOf(
        {wrapped(wave['timings_ms'], 'L')})

    /** Step amplitudes, 0–255. */
    val AMPLITUDES = intArrayOf(
        {wrapped(wave['amplitudes'])})

    /** API 26+: loops from the first step until cancelled (needs amplitude control). */
    fun waveform(): VibrationEffect = VibrationEffect.createWaveform(TIMINGS, AMPLITUDES, 0)

    /** API 36+: amplitude and frequency envelope; frequencies the device cannot play are not
     *  played (see Vibrator.getFrequencyProfile()). Starts and ends at amplitude 0. */
    fun waveformEnvelope(): VibrationEffect = VibrationEffect.WaveformEnvelopeBuilder()
        .setInitialFrequencyHz({wenv['initial_frequency_hz']}f){wave_points}
        .build()

    /** API 36+: intensity and sharpness envelope, adapted to the device by the framework. */
    fun basicEnvelope(): VibrationEffect = VibrationEffect.BasicEnvelopeBuilder()
        .setInitialSharpness({benv['initial_sharpness']}f){basic_points}
        .build()
}}
"""


def build(pattern: TactilePattern, coupling=None, *, repeats: int = 1, name: str = "pattern",
          tool: str = "", version: str | None = None) -> dict:
    """The Android export document (JSON-ready dict), with the Kotlin snippet as lines.

    Args:
        pattern: the tactile pattern.
        coupling: the Eq. 1 constants, copied into the document (``"coupling"``) when given,
            for the app that scales the vibration with pressure and speed.
        repeats: periods laid end to end.
        name, tool: name the Kotlin object and the comments.
        version: recorded as ``profile_version`` (default: the pattern's version).
    """
    pattern = check_pattern(pattern)
    repeats = check_span(pattern, repeats, name)
    measured = env.measure(pattern.samples, pattern.rate, source=name)
    waveform_env, basic_env = envelopes(measured, repeats)
    count = len(basic_env["control_points"])
    document = {
        "format": "realpen-android-vibration", "version": 1,
        "generator": f"RealPen {__version__}",
        "name": name, "tool": tool, "profile_version": version or pattern.version,
        "period_ms": pattern.frames / pattern.rate * 1000, "repeats": repeats,
        "waveform": waveform(measured, repeats),
        "waveform_envelope": waveform_env, "basic_envelope": basic_env,
        "notes": [f"envelopes: {count} control points; every envelope-capable device takes "
                  f"{GUARANTEED_POINTS} (check VibratorEnvelopeEffectInfo.getMaxSize())",
                  "envelope frequencies are the pattern's spectral centroid in Hz; check "
                  "Vibrator.getFrequencyProfile() for the device's range"],
    }
    if coupling is not None:
        document["coupling"] = coupling.to_json()
    document["kotlin"] = kotlin(document).splitlines()
    return document


def export(pattern: TactilePattern, sound=None, coupling=None, *, name: str = "pattern",
           tool: str = "", version: str | None = None, repeats: int = 1,
           kotlin_only: bool = False) -> Export:
    """Render the Android JSON (or, with ``kotlin_only``, just the Kotlin source).

    ``sound`` is not carried; ``coupling`` is copied into the JSON when given.
    """
    document = build(pattern, coupling, repeats=repeats, name=name, tool=tool, version=version)
    steps = len(document["waveform"]["timings_ms"])
    if kotlin_only:
        data = ("\n".join(document["kotlin"]) + "\n").encode("utf-8")
        what = "Kotlin object"
    else:
        data = (json.dumps(document, indent=2, allow_nan=False) + "\n").encode("utf-8")
        what = "JSON with a Kotlin snippet"
    return Export(data, f"{what}: waveform of {steps} steps (loops), envelopes of "
                        f"{len(document['basic_envelope']['control_points'])} control points",
                  limits=LIMITS + residual_limits(pattern, RESIDUAL_IN_ENVELOPE))
