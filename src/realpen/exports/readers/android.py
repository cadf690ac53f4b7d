"""Read RealPen's Android export (``format: "realpen-android-vibration"``) and render its
``createWaveform`` effect as a phone with frequency control would play it.

The JSON (:mod:`realpen.exports.android`) holds three forms of one vibration. The one rendered
is ``waveform``, the ``VibrationEffect.createWaveform(timings, amplitudes, repeat)`` arrays
(the only form that loops seamlessly): step ``i`` holds amplitude ``amplitudes[i] / 255`` for
``timings_ms[i]`` ms (Android's steps are constant, not ramps). ``createWaveform`` carries no
frequency; the model takes it from ``waveform_envelope`` (the ``WaveformEnvelopeBuilder``
form): from ``initial_frequency_hz`` at 0, each control point's ``frequency_hz`` reached
linearly over its ``duration_ms``, held after the last. The vibration is the shared carrier of
:mod:`realpen.exports.readers.carrier` at that frequency. One pass is rendered; ``repeat``
says where a phone loops from until ``cancel()``. The ``basic_envelope`` form is read for the
summary only.

Any other JSON is refused in one line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from realpen.exports.android import MAX_AMPLITUDE
from realpen.exports.readers import carrier
from realpen.exports.readers.fields import (
    Playback,
    array,
    check_parts,
    check_play_time,
    integer,
    member,
    number,
    problem,
    text,
    where,
)

__all__ = ["FORMAT", "VERSION", "read"]

FORMAT = "realpen-android-vibration"
VERSION = 1
_NOTE = ("the createWaveform steps rendered (amplitude/255 held for each step) on a sine whose "
         "frequency follows the waveform envelope's control points (Hz, linear over each "
         "duration); createWaveform itself carries no frequency")


def _waveform(document: dict, source: Path) -> tuple[np.ndarray, np.ndarray, int]:
    wave = member(document, "waveform", source, "")
    timings = array(member(wave, "timings_ms", source, "waveform"), source,
                    "waveform.timings_ms", min_items=1)
    amplitudes = array(member(wave, "amplitudes", source, "waveform"), source,
                       "waveform.amplitudes", min_items=1)
    check_parts(len(timings), "waveform steps", source)
    if len(timings) != len(amplitudes):
        raise problem(source, "waveform.amplitudes",
                      f"must hold one amplitude per timing ({len(amplitudes)} amplitudes, "
                      f"{len(timings)} timings)")
    steps_ms = np.array([integer(value, source, where("waveform.timings_ms", index), low=0)
                         for index, value in enumerate(timings)], dtype=np.float64)
    levels = np.array([integer(value, source, where("waveform.amplitudes", index), low=0,
                               high=MAX_AMPLITUDE)
                       for index, value in enumerate(amplitudes)], dtype=np.float64)
    repeat = integer(member(wave, "repeat", source, "waveform", required=False, default=-1),
                     source, "waveform.repeat", low=-1, high=len(timings) - 1)
    return steps_ms, levels / MAX_AMPLITUDE, repeat


def _frequency(document: dict, source: Path) -> tuple[np.ndarray, np.ndarray]:
    """Breakpoints (s, Hz) of the waveform envelope's frequency."""
    at = "waveform_envelope"
    envelope = member(document, at, source, "")
    start = number(member(envelope, "initial_frequency_hz", source, at), source,
                   where(at, "initial_frequency_hz"), low=1.0)
    points = array(member(envelope, "control_points", source, at), source,
                   where(at, "control_points"), min_items=1)
    times, hz = [0.0], [start]
    for index, point in enumerate(points):
        here = where(where(at, "control_points"), index)
        duration = integer(member(point, "duration_ms", source, here), source,
                           where(here, "duration_ms"), low=0)
        hz.append(number(member(point, "frequency_hz", source, here), source,
                         where(here, "frequency_hz"), low=1.0))
        times.append(times[-1] + duration / 1000)
    return np.array(times), np.array(hz)


def read(document: dict, source: Path) -> Playback:
    """Read a parsed Android export document.

    Args:
        document: the file's JSON.
        source: the file, for messages.

    Raises:
        RealPenError: one line naming the file: not RealPen's Android export, or a field that
            breaks it.
    """
    kind = document.get("format")
    if kind != FORMAT:
        raise problem(source, "format", f"is not RealPen's Android export (format '{FORMAT}'), "
                                        f"got {kind!r}")
    version = integer(member(document, "version", source, ""), source, "version", low=1)
    if version != VERSION:
        raise problem(source, "version", f"must be {VERSION}, got {version}")
    name = text(document.get("name", ""), source, "name")
    steps_ms, levels, repeat = _waveform(document, source)
    freq_times, freq_hz = _frequency(document, source)
    basic = document.get("basic_envelope")
    basic_points = 0 if basic is None else len(array(
        member(basic, "control_points", source, "basic_envelope"), source,
        "basic_envelope.control_points"))
    edges = np.concatenate([[0.0], np.cumsum(steps_ms)]) / 1000
    duration_s = check_play_time(float(edges[-1]), source)

    def render(rate: int) -> np.ndarray:
        t = carrier.sample_times(duration_s, rate)
        step = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, len(levels) - 1)
        return carrier.carrier(levels[step], carrier.linear(freq_times, freq_hz, t), rate)

    summary = (f"Android vibration{f' {name!r}' if name else ''}: waveform of {len(levels)} "
               f"steps over {duration_s * 1000:g} ms (repeat {repeat}), envelopes of "
               f"{len(freq_hz) - 1} and {basic_points} control points")
    notes = (_NOTE, "one pass rendered" + (f"; a phone loops from step {repeat} until "
                                           f"cancel()" if repeat >= 0 else ""))
    return Playback(duration_s, summary, render, notes)
