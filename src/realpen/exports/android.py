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
points (``VibratorEnvelopeEffectInfo.getMaxSize()``: "a minimum of 16"), control-point
durations from 20 ms (``getMinControlPointDurationMillis()``) and up to 1 s
(``getMaxControlPointDurationMillis()``), and so 16 s in all. So the envelopes use up to 14
segments per period (each ≥ 40 ms): a first point reached from 0 at the first segment's centre,
one per further segment, one at the period's end holding the wrap value and a final 20 ms ramp
to 0 — 16 points for one period.

Limits, checked before anything is written (each refusal one line naming the limit):

- one period only (``repeats`` = 1): a second period would need 30 control points, more than
  every device takes — and ``createWaveform`` loops by itself (``repeat`` 0), the envelopes with
  ``createRepeatingEffect``;
- a period from 40 ms (two 20 ms control points) to 14 s (14 segments of at most 1 s); the
  control points made are checked again: at most 16, each 20 ms … 1 s;
- ``createWaveform`` timings above 0 ms (Android ignores a step of 0 ms) and amplitudes
  0 … 255;
- the frequency profile stays a note: which frequencies a vibrator plays is known only on the
  device (``Vibrator.getFrequencyProfile()``).

The coupling. Given the Eq. 1 constants (:class:`realpen.motion.coupling.Coupling`), the JSON
copies them and the Kotlin object carries them with ``gain(pressure, speedMmS)`` — the gain
exactly as :meth:`~realpen.motion.coupling.Coupling.gain_raw` computes it (clamped to
``[0, a_max]``, 0 when lifted) — and ``waveform(pressure, speedMmS)``, the looping waveform
with its amplitudes scaled by ``gain / a_max``: the pattern is peak-normalised, so full drive
is reached at ``a_max`` (the live app's rule for the tactile channel). RealPen's 5 ms smoothing
of the gain is not applied: each new effect restarts the waveform, so an app sends one only
when the drive has changed noticeably.

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
from realpen.errors import ParameterError, fail
from realpen.exports import envelope as env
from realpen.exports.base import (
    RESIDUAL_IN_ENVELOPE,
    Export,
    check_pattern,
    check_span,
    residual_limits,
)
from realpen.tactile.pattern import TactilePattern

__all__ = ["SUFFIX", "KOTLIN_SUFFIX", "ENVELOPE_SEGMENTS", "MIN_POINT_MS", "MAX_POINT_MS",
           "GUARANTEED_POINTS", "MIN_PERIOD_MS", "MAX_PERIOD_MS", "MAX_AMPLITUDE", "LIMITS",
           "check_period", "check_waveform", "check_envelope", "waveform", "envelopes",
           "kotlin", "build", "export"]

SUFFIX = ".json"
KOTLIN_SUFFIX = ".kt"
ENVELOPE_SEGMENTS = 14  # + wrap point + final zero = 16, the guaranteed maximum
MIN_POINT_MS = 20  # shortest control-point duration every envelope-capable device takes
MAX_POINT_MS = 1000  # longest control-point duration every envelope-capable device takes
GUARANTEED_POINTS = 16
MIN_PERIOD_MS = 2 * MIN_POINT_MS
"""The shortest period (ms) the envelopes hold: one segment, reached and left in 20 ms halves."""
MAX_PERIOD_MS = ENVELOPE_SEGMENTS * MAX_POINT_MS
"""The longest period (ms) the envelopes hold: 14 segments of at most 1 s."""
MAX_AMPLITUDE = 255  # createWaveform's full amplitude
_FLOAT_MAX = 3.4028234663852886e38  # a Kotlin Float literal beyond this does not compile
LIMITS = (
    "one amplitude and one frequency at a time: the RMS envelope and the spectral centroid",
    "only the createWaveform form loops seamlessly; envelope forms restart from amplitude 0",
    "the sound is not carried",
)


def check_period(period_ms: float, repeats: int, name: str = "pattern") -> None:
    """Refuse what the Android envelopes cannot hold on every device, before measuring.

    Args:
        period_ms: the tactile pattern's period in ms.
        repeats: periods asked for (checked whole and positive already).
        name: names the pen in an error.

    Raises:
        ParameterError: (parameter ``repeats``) more than one period.
        RealPenError: a period shorter than :data:`MIN_PERIOD_MS` or longer than
            :data:`MAX_PERIOD_MS`.
    """
    if repeats > 1:
        raise ParameterError("repeats", f"an Android export holds one period: {repeats} "
                                        f"periods need {ENVELOPE_SEGMENTS * repeats + 2} "
                                        f"envelope control points, and devices guarantee "
                                        f"{GUARANTEED_POINTS} (createWaveform loops by itself)")
    if period_ms < MIN_PERIOD_MS:
        raise fail(name, f"the tactile pattern lasts {period_ms:g} ms; Android envelope "
                         f"control points last at least {MIN_POINT_MS} ms, so a period needs "
                         f"{MIN_PERIOD_MS} ms")
    if period_ms > MAX_PERIOD_MS:
        raise fail(name, f"the tactile pattern lasts {period_ms:g} ms; Android envelopes hold "
                         f"{GUARANTEED_POINTS} control points at most {MAX_POINT_MS} ms apart "
                         f"on every device, so a period of at most {MAX_PERIOD_MS} ms")


def check_waveform(wave: dict, name: str = "pattern") -> dict:
    """``wave`` (see :func:`waveform`) if ``createWaveform`` plays every step as written.

    Raises:
        RealPenError: a timing of 0 ms or less (Android drops a 0 ms step) or an amplitude
            outside 0 … 255, naming the step.
    """
    for index, (timing, amplitude) in enumerate(zip(wave["timings_ms"], wave["amplitudes"])):
        if timing <= 0:
            raise fail(name, f"createWaveform step {index} lasts {timing} ms; Android needs "
                             f"timings above 0 ms")
        if not 0 <= amplitude <= MAX_AMPLITUDE:
            raise fail(name, f"createWaveform step {index} has amplitude {amplitude}; Android "
                             f"takes 0 … {MAX_AMPLITUDE}")
    return wave


def check_envelope(envelope: dict, name: str = "pattern") -> dict:
    """``envelope`` (a builder's control points, see :func:`envelopes`) if every
    envelope-capable device plays it: at most :data:`GUARANTEED_POINTS` control points, each
    lasting :data:`MIN_POINT_MS` … :data:`MAX_POINT_MS`.

    Raises:
        RealPenError: one line naming the limit broken.
    """
    points = envelope["control_points"]
    if len(points) > GUARANTEED_POINTS:
        raise fail(name, f"the Android envelope has {len(points)} control points; devices "
                         f"guarantee {GUARANTEED_POINTS} (VibratorEnvelopeEffectInfo.getMaxSize)")
    for index, point in enumerate(points):
        if not MIN_POINT_MS <= point["duration_ms"] <= MAX_POINT_MS:
            raise fail(name, f"Android envelope control point {index} lasts "
                             f"{point['duration_ms']} ms; devices guarantee {MIN_POINT_MS} … "
                             f"{MAX_POINT_MS} ms (VibratorEnvelopeEffectInfo)")
    return envelope


def waveform(measured: env.Envelope, repeats: int = 1) -> dict:
    """``createWaveform`` arrays of a measured pattern: one step per frame, ``repeats`` periods.

    Returns:
        ``timings_ms`` (ints), ``amplitudes`` (ints 0 … 255, the frame RMS relative to the
        loudest frame) and ``repeat`` 0 (loop from the first step).
    """
    edges_ms = np.round(measured.edges_s * 1000).astype(int)
    timings = np.tile(np.diff(edges_ms), repeats)
    amplitudes = np.tile(np.clip(np.rint(MAX_AMPLITUDE * measured.intensity), 0,
                                 MAX_AMPLITUDE).astype(int), repeats)
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


def _kotlin_float(value: float) -> str:
    """A Kotlin ``Float`` literal of ``value``: its shortest round-trip decimal, ``f``."""
    text = repr(float(value))
    return (text if any(c in text for c in ".e") else text + ".0") + "f"


def _coupling_kotlin(coupling: dict) -> str:
    """The Kotlin members that apply Eq. 1 with the export's coupling constants."""
    values = {key: _kotlin_float(coupling[key]) for key in ("c_p", "c_op", "c_x", "c_ov", "a_max")}
    return f"""
    // Eq. 1 of the method with the profile's constants: A_s = C_P·(P − C_OP) + C_X·(v − C_OV),
    // clamped to [0, A_MAX] and 0 when the pen is lifted (P <= 0). P is the pen's pressure,
    // 0–1 (MotionEvent.getPressure()); v its speed in mm/s (px/s ÷ (DisplayMetrics.xdpi / 25.4)).
    const val C_P = {values['c_p']}  // gain per unit of pressure
    const val C_OP = {values['c_op']}  // pressure offset, 0–1
    const val C_X = {values['c_x']}  // gain per mm/s
    const val C_OV = {values['c_ov']}  // speed offset, mm/s
    const val A_MAX = {values['a_max']}  // largest gain (full drive)

    /** Eq. 1: the gain for pressure 0–1 and speed in mm/s, 0 … A_MAX. */
    fun gain(pressure: Float, speedMmS: Float): Float {{
        if (pressure <= 0f) return 0f
        val value = C_P * (pressure - C_OP) + C_X * (speedMmS - C_OV)
        return value.coerceIn(0f, A_MAX)
    }}

    /** API 26+: the looping waveform, its amplitudes scaled by gain / A_MAX (the pattern is
     *  peak-normalised: full drive at A_MAX), nonzero steps kept within 1–255; null when the
     *  gain is 0 (call vibrator.cancel()). Each new effect restarts the pattern: send one when
     *  the drive has changed noticeably, not on every touch sample. */
    fun waveform(pressure: Float, speedMmS: Float): VibrationEffect? {{
        val drive = gain(pressure, speedMmS) / A_MAX
        if (drive <= 0f) return null
        val scaled = IntArray(AMPLITUDES.size) {{ i ->
            if (AMPLITUDES[i] == 0) 0 else (AMPLITUDES[i] * drive).roundToInt().coerceIn(1, 255)
        }}
        return VibrationEffect.createWaveform(TIMINGS, scaled, 0)
    }}
"""


def kotlin(document: dict) -> str:
    """A short Kotlin object holding the three effects of an Android export document, and,
    when the document has ``coupling``, ``gain()`` and ``waveform(pressure, speedMmS)``
    applying Eq. 1 (see the module docstring)."""
    name = document["name"]
    obj = "".join(part.capitalize() for part in re.split(r"[^A-Za-z0-9]+", name) if part)
    obj = ("Pen" + obj if obj[:1].isdigit() else obj) + "Vibration"
    wave = document["waveform"]
    wenv, benv = document["waveform_envelope"], document["basic_envelope"]

    def points(entries: list[dict], first: str, second: str) -> str:
        return "".join(f"\n        .addControlPoint({p[first]}f * drive, {p[second]}f, "
                       f"{p['duration_ms']}L)"
                       for p in entries)

    def wrapped(values: list[int], suffix: str = "") -> str:
        items = [f"{v}{suffix}" for v in values]
        return ",\n        ".join(", ".join(items[i:i + 15]) for i in range(0, len(items), 15))

    wave_points = points(wenv["control_points"], "amplitude", "frequency_hz")
    basic_points = points(benv["control_points"], "intensity", "sharpness")
    period = document["period_ms"]
    tool = " ".join(document["tool"].split())  # one comment line
    label = f"'{name}' ({tool})" if tool else f"'{name}'"
    coupling = document.get("coupling")
    if coupling is None:
        play, imports, coupled = "waveform()", "import android.os.VibrationEffect", ""
        drive_hint = ""
    else:
        drive_hint = ": gain(pressure, speedMmS) / A_MAX"
        play = "waveform(pressure, speedMmS)"
        imports = "import android.os.VibrationEffect\nimport kotlin.math.roundToInt"
        coupled = _coupling_kotlin(coupling)
    return f"""// RealPen {label}: {period:g} ms tactile pattern.
// Generated by RealPen {__version__}; do not edit. Play {play} while the pen
// moves on the surface and call vibrator.cancel() when it lifts.
{imports}

object {obj} {{
    /** Step durations in ms; with AMPLITUDES, one period of the pattern. */
    val TIMINGS = longArrayOf(
        {wrapped(wave['timings_ms'], 'L')})

    /** Step amplitudes, 0–255. */
    val AMPLITUDES = intArrayOf(
        {wrapped(wave['amplitudes'])})

    /** API 26+: loops from the first step until cancelled (needs amplitude control). */
    fun waveform(): VibrationEffect = VibrationEffect.createWaveform(TIMINGS, AMPLITUDES, 0)
{coupled}
    /** API 36+: amplitude and frequency envelope; frequencies the device cannot play are not
     *  played (see Vibrator.getFrequencyProfile()). Starts and ends at amplitude 0.
     *  drive (0–1{drive_hint}) scales the amplitudes. */
    fun waveformEnvelope(drive: Float = 1f): VibrationEffect = VibrationEffect.WaveformEnvelopeBuilder()
        .setInitialFrequencyHz({wenv['initial_frequency_hz']}f){wave_points}
        .build()

    /** API 36+: intensity and sharpness envelope, adapted to the device by the framework.
     *  drive (0–1{drive_hint}) scales the intensities. */
    fun basicEnvelope(drive: Float = 1f): VibrationEffect = VibrationEffect.BasicEnvelopeBuilder()
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
            and applied by the Kotlin's ``waveform(pressure, speedMmS)``.
        repeats: periods laid end to end: 1 (see the module docstring).
        name, tool: name the Kotlin object and the comments.
        version: recorded as ``profile_version`` (default: the pattern's version).

    Raises:
        ParameterError: ``repeats`` other than 1.
        RealPenError: a limit of the module docstring broken, or coupling constants beyond
            a Kotlin ``Float``.
    """
    pattern = check_pattern(pattern)
    repeats = check_span(pattern, repeats, name)
    check_period(pattern.frames / pattern.rate * 1000, repeats, name)
    if coupling is not None:
        for key in ("c_p", "c_op", "c_x", "c_ov", "a_max"):
            if abs(getattr(coupling, key)) > _FLOAT_MAX:
                raise fail(name, f"the coupling's {key} ({getattr(coupling, key):g}) is beyond "
                                 f"a Kotlin Float")
    measured = env.measure(pattern.samples, pattern.rate, source=name)
    waveform_env, basic_env = envelopes(measured, repeats)
    for envelope in (waveform_env, basic_env):
        check_envelope(envelope, name)
    count = len(basic_env["control_points"])
    document = {
        "format": "realpen-android-vibration", "version": 1,
        "generator": f"RealPen {__version__}",
        "name": name, "tool": tool, "profile_version": version or pattern.version,
        "period_ms": pattern.frames / pattern.rate * 1000, "repeats": repeats,
        "waveform": check_waveform(waveform(measured, repeats), name),
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
