"""Read an MPEG-I haptics interchange file (``.hjif``, ISO/IEC 23090-31) and render it as the
MPEG reference software plays it.

Read: every perception's channels, each channel's bands, each band's effects. A channel plays
the sum of its bands, scaled by its ``gain``; channels are summed into the one vibration
rendered (RealPen's exports hold one). Positions are in ticks of ``timescale`` (default 1000).

- ``VectorialWave`` bands: ``Basis`` effects. An effect sounds from its ``position`` through
  its last keyframe. Its amplitude is linear between the keyframes that carry
  ``amplitude_modulation`` (held before the first and after the last). Its frequency (Hz) is
  that of the keyframes carrying ``frequency_modulation``: one such keyframe holds for the
  whole effect, ``base_signal(2π·f·t + phase)`` with ``t`` in seconds from the effect's
  position; between several, the frequency glides linearly and the phase is its integral in
  seconds. (The reference renderer advances the phase between frequency keyframes as if
  positions were milliseconds whatever the ``timescale``, so such a file plays differently
  there unless the timescale is 1000; RealPen writes one frequency keyframe per effect.)
  Base signals: ``Sine``, ``Square``, ``Triangle``, ``SawToothUp``, ``SawToothDown``, as the
  reference software defines them.
- ``Curve`` bands: the amplitude keyframes joined linearly (the reference software's
  ``Linear`` curve type; other curve types are read as linear and the notes say so).
- ``Transient`` bands: each keyframe a 22 ms burst ``a·sin(4π·t/22 ms)``, as the reference
  software plays it.
- ``WaveletWave`` bands and ``Composite``/``Reference`` effects are refused (one line).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

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

__all__ = ["DEFAULT_TIMESCALE", "TRANSIENT_S", "BASE_SIGNALS", "MAX_RENDER_SAMPLES", "read"]

DEFAULT_TIMESCALE = 1000  # ticks per second when the file gives none (the standard's default)
TRANSIENT_S = 0.022  # the reference software's transient length
BASE_SIGNALS = ("Sine", "Square", "Triangle", "SawToothUp", "SawToothDown")
MAX_RENDER_SAMPLES = 2**30
"""The most effect samples one render computes (the effects' spans summed, at the render's
rate): the pencil's largest export (100 periods, 31,000 effects spanning 1,571 s in all) is
6·10⁸ at 384 kHz."""
_VERSION = re.compile(r"^[0-9]{4}(-[0-9])?$")


@dataclass(frozen=True)
class _Effect:
    position: int  # ticks
    times: np.ndarray  # keyframe positions relative to the effect, ticks
    amplitude_at: np.ndarray  # positions of the amplitude keyframes, ticks
    amplitudes: np.ndarray
    frequency_at: np.ndarray  # positions of the frequency keyframes, ticks
    frequencies: np.ndarray  # Hz
    phase: float  # rad
    base: str

    @property
    def end(self) -> int:
        """The last tick the effect sounds at."""
        return self.position + (int(self.times[-1]) if len(self.times) else 0)


@dataclass(frozen=True)
class _Band:
    kind: str
    effects: list[_Effect]
    gain: float


def _waveform(base: str, cycles: np.ndarray) -> np.ndarray:
    """The reference software's base signals of ``cycles`` (periods since the phase origin)."""
    if base == "Sine":
        return np.sin(2 * np.pi * cycles)
    if base == "Square":
        return 1 - 2 * np.round(cycles - np.floor(cycles))
    if base == "Triangle":
        return 1 - 4 * np.abs(np.round(cycles - 0.25) - (cycles - 0.25))
    if base == "SawToothUp":
        return 2 * (cycles - np.floor(cycles + 0.5))
    return 2 * (np.floor(cycles + 0.5) - cycles)  # SawToothDown


def _cycles(effect: _Effect, relative: np.ndarray, timescale: int) -> np.ndarray:
    """Periods of an effect's carrier at ``relative`` ticks from its position."""
    origin = effect.phase / (2 * np.pi)
    at, hz = effect.frequency_at, effect.frequencies
    if len(hz) == 0:
        return np.full(relative.shape, origin)
    if len(hz) == 1:
        return origin + hz[0] * relative / timescale
    # Piecewise-linear frequency: integrate it exactly (trapezoids are exact for linear pieces).
    knots = np.concatenate([[min(0.0, float(at[0]))], at, [max(float(relative.max(initial=0)),
                                                                float(at[-1]))]])
    knot_hz = np.concatenate([[hz[0]], hz, [hz[-1]]])
    area = np.concatenate([[0.0], np.cumsum(np.diff(knots) * (knot_hz[1:] + knot_hz[:-1]) / 2)])
    index = np.clip(np.searchsorted(knots, relative, side="right") - 1, 0, len(knots) - 2)
    span = np.diff(knots)[index]
    slope = np.divide(np.diff(knot_hz)[index], span, out=np.zeros_like(relative), where=span > 0)
    offset = relative - knots[index]
    inside = area[index] + offset * (knot_hz[index] + slope * offset / 2)
    start = np.interp(0.0, knots, area) if knots[0] < 0 else 0.0
    return origin + (inside - start) / timescale


def _render_band(band: _Band, count: int, rate: int, timescale: int) -> np.ndarray:
    out = np.zeros(count)
    ticks_per_sample = timescale / rate
    for effect in band.effects:
        if band.kind == "Transient":
            length = TRANSIENT_S * timescale
            for at, amplitude in zip(effect.amplitude_at, effect.amplitudes):
                start = effect.position + at
                first = int(np.ceil(start / ticks_per_sample))
                last = min(count - 1, int(np.floor((start + length) / ticks_per_sample)))
                if last < first:
                    continue
                relative = np.arange(first, last + 1) * ticks_per_sample - start
                out[first:last + 1] += amplitude * np.sin(4 * np.pi * relative / length)
            continue
        first = int(np.ceil(effect.position / ticks_per_sample))
        last = min(count - 1, int(np.floor(effect.end / ticks_per_sample)))
        if last < first:
            continue
        relative = np.arange(first, last + 1) * ticks_per_sample - effect.position
        level = (np.interp(relative, effect.amplitude_at, effect.amplitudes)
                 if len(effect.amplitudes) else np.ones_like(relative))
        if band.kind == "Curve":
            out[first:last + 1] += level
        else:
            out[first:last + 1] += level * _waveform(effect.base,
                                                     _cycles(effect, relative, timescale))
    return band.gain * out


def _effect(raw: object, source: Path, at: str, kind: str) -> _Effect:
    effect_type = text(member(raw, "effect_type", source, at), source,
                       where(at, "effect_type"), choices=("Basis", "Composite", "Reference"))
    if effect_type != "Basis":
        raise problem(source, where(at, "effect_type"),
                      f"{effect_type} effects are not read (RealPen reads Basis effects)")
    position = integer(member(raw, "position", source, at, required=False, default=0),
                       source, where(at, "position"), low=0)
    phase = number(member(raw, "phase", source, at, required=False, default=0.0), source,
                   where(at, "phase"), low=0.0, high=6.28318)
    base = text(member(raw, "base_signal", source, at, required=False, default="Sine"),
                source, where(at, "base_signal"), choices=BASE_SIGNALS)
    frames = array(member(raw, "keyframes", source, at, required=False, default=[]), source,
                   where(at, "keyframes"))
    times, amp_at, amps, freq_at, freqs = [], [], [], [], []
    for index, frame in enumerate(frames):
        here = where(where(at, "keyframes"), index)
        tick = integer(member(frame, "relative_position", source, here, required=False,
                              default=0), source, where(here, "relative_position"), low=0)
        if times and tick < times[-1]:
            raise problem(source, where(here, "relative_position"),
                          f"keyframes must be in time order ({tick} after {times[-1]})")
        times.append(tick)
        if "amplitude_modulation" in frame:
            amp_at.append(tick)
            amps.append(number(frame["amplitude_modulation"], source,
                               where(here, "amplitude_modulation"), low=-1.0, high=1.0))
        if "frequency_modulation" in frame:
            freq_at.append(tick)
            freqs.append(number(frame["frequency_modulation"], source,
                                where(here, "frequency_modulation"), low=0.0, high=10000.0))
    if kind == "VectorialWave" and not times:
        raise problem(source, where(at, "keyframes"), "a VectorialWave effect needs keyframes")
    if kind in ("Curve", "Transient") and not amps:
        raise problem(source, where(at, "keyframes"),
                      f"a {kind} effect needs keyframes with amplitude_modulation")
    return _Effect(position, np.array(times, dtype=float), np.array(amp_at, dtype=float),
                   np.array(amps), np.array(freq_at, dtype=float), np.array(freqs), phase, base)


def _bands(document: dict, source: Path) -> tuple[list[_Band], list[str], int]:
    notes: list[str] = []
    perceptions = array(member(document, "perceptions", source, ""), source, "perceptions",
                        min_items=1)
    bands: list[_Band] = []
    channels = counted = 0
    for p_index, perception in enumerate(perceptions):
        p_at = where("perceptions", p_index)
        for c_index, channel in enumerate(array(member(perception, "channels", source, p_at),
                                                source, where(p_at, "channels"), min_items=1)):
            c_at = where(where(p_at, "channels"), c_index)
            channels += 1
            gain = number(member(channel, "gain", source, c_at), source, where(c_at, "gain"),
                          low=0.0)
            for b_index, band in enumerate(array(member(channel, "bands", source, c_at),
                                                 source, where(c_at, "bands"))):
                b_at = where(where(c_at, "bands"), b_index)
                kind = text(member(band, "band_type", source, b_at), source,
                            where(b_at, "band_type"),
                            choices=("WaveletWave", "VectorialWave", "Curve", "Transient"))
                if kind == "WaveletWave":
                    raise problem(source, where(b_at, "band_type"),
                                  "WaveletWave bands are not read (RealPen reads "
                                  "VectorialWave, Curve and Transient bands)")
                curve = text(member(band, "curve_type", source, b_at, required=False,
                                    default="Linear"), source, where(b_at, "curve_type"))
                if kind == "Curve" and curve != "Linear":
                    notes.append(f"{b_at}: a {curve} curve is read as linear")
                effects = array(member(band, "effects", source, b_at), source,
                                where(b_at, "effects"))
                counted = check_parts(counted + len(effects), "effects", source)
                bands.append(_Band(kind, [_effect(e, source, where(where(b_at, "effects"), i),
                                                  kind) for i, e in enumerate(effects)], gain))
    if channels > 1:
        notes.append(f"{channels} channels summed into one vibration, each scaled by its gain")
    return bands, notes, channels


def read(document: dict, source: Path) -> Playback:
    """Read a parsed ``.hjif`` document.

    Args:
        document: the file's JSON.
        source: the file, for messages.

    Raises:
        RealPenError: one line naming the file and the field that breaks the format.
    """
    version = text(member(document, "version", source, ""), source, "version")
    if not _VERSION.match(version):
        raise problem(source, "version", f"must be a year (YYYY or YYYY-N), got {version!r}")
    timescale = integer(member(document, "timescale", source, "", required=False,
                               default=DEFAULT_TIMESCALE), source, "timescale", low=1)
    bands, notes, channels = _bands(document, source)
    effects = [effect for band in bands for effect in band.effects]
    transient_ticks = TRANSIENT_S * timescale
    ends = [effect.end + (transient_ticks if band.kind == "Transient" else 0)
            for band in bands for effect in band.effects]
    duration_s = check_play_time((max(ends) + 1) / timescale if ends else 0.0, source)
    # Each effect is rendered over its own span: the work is the spans' sum, not the length.
    spans_s = sum(float(end - effect.position) / timescale
                  for end, effect in zip(ends, effects))

    def render(rate: int) -> np.ndarray:
        if spans_s * rate > MAX_RENDER_SAMPLES:
            raise problem(source, "", f"its {len(effects):,} effects span {spans_s:g} s in all: "
                                      f"{spans_s * rate:,.0f} samples at {rate} Hz; RealPen "
                                      f"renders at most {MAX_RENDER_SAMPLES:,}")
        count = int(round(duration_s * rate))
        out = np.zeros(count)
        for band in bands:
            out += _render_band(band, count, rate, timescale)
        return out

    kinds = sorted({band.kind for band in bands})
    summary = (f"{len(effects)} effects in {len(bands)} band(s) ({', '.join(kinds) or 'none'}) "
               f"of {channels} channel(s), {duration_s * 1000:g} ms at timescale {timescale}/s")
    return Playback(duration_s, summary, render, tuple(notes))
