"""Accelerometer captures from the pen: SAMPLES blocks → acceleration in m/s² on the sensor's grid.

The pen's LIS3DH samples at its own clock: 1344 Hz nominal, a few per cent off in a real part.
Each SAMPLES block (:class:`~realpen.device.client.SampleBlock`) carries the index of its first
sample since CAPTURE_START and the pen's µs clock when the sensor's FIFO was read, so the host
knows where every sample belongs and can tell the true rate from the pen's clock:

- **Placement.** Samples go to their index on one grid. An index that jumps is a gap: blocks the
  pen could not send (``"dropped"``: exactly that many samples are missing) or samples lost
  inside the sensor when its FIFO overran (``"overrun"``: the block is flagged, and the pen's
  count of the lost samples is only an estimate). After an overrun the blocks' times say how
  many samples were really lost: the host measures it to the nearest sample from the pen's
  clock and places the samples after it there, so a tone keeps its phase across the gap. A
  lasting step of the clock with no flag (the FIFO overwrote samples between the pen's look
  at its level and its read) is found the same way and becomes an overrun gap too. Gaps are
  NaN in :attr:`Capture.samples`, 0 in the files written.
- **Rate.** A least-squares line through (index of each block's last sample, its ``t_us``):
  the block's last sample was taken at most one sample period (plus the pen's read latency)
  before ``t_us``, a jitter the fit averages out; blocks more than five robust deviations off
  the line (a pen busy elsewhere) are left out. An overrun's estimated count, or a step of the
  clock, would bend the line, so each stretch between them has its own intercept and all share
  the slope. The
  standard error of the slope gives the rate's uncertainty (e.g. 1366.85 ± 0.02 Hz for 10 s).
  The pen's clock is taken as the reference: its crystal is good to tens of ppm.
- **Scaling.** High-resolution mode: 12 bits, left-justified. ``g = (raw >> 4) × mg/digit /
  1000`` with 1, 2, 4 and 12 mg per digit at ±2, 4, 8 and 16 g. A sample at either end of the
  12-bit range is counted as clipped.

:class:`CaptureAssembler` does all of this block by block (with a live level meter);
:func:`record` runs a capture on a :class:`~realpen.device.client.PenClient`;
:func:`write_capture` writes a WAV, NPZ or CSV that :func:`realpen.io.recording.load_recording`
reads back at the estimated rate.

Example (a capture of two blocks, made here rather than by a pen)::

    >>> from realpen.device.client import SampleBlock
    >>> assembler = CaptureAssembler(range_g=2)
    >>> raw = np.full((32, 3), 1000 << 4, dtype=np.int16)  # 1000 digits: 1 g at ±2 g
    >>> assembler.feed(SampleBlock(0, 23_810, 2, 0, raw, 0.0))
    >>> assembler.feed(SampleBlock(64, 71_430, 2, 0, raw, 0.1))  # the block of 32..63 was lost
    >>> capture = assembler.result()
    >>> capture.samples.shape, capture.gaps
    ((96, 3), [Gap(at_s=0.0238..., samples_lost=32, kind='dropped')])
    >>> round(float(capture.samples[0, 0]), 5)
    9.80665
"""

from __future__ import annotations

import json
import math
import platform
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import NamedTuple

import numpy as np

from realpen.checks import require_number
from realpen.device import protocol as p
from realpen.device.client import PenClient, PenEvent, PenInfo, SampleBlock
from realpen.device.transport import DeviceError
from realpen.errors import ParameterError, fail
from realpen.io.files import atomic_path
from realpen.io.recording import CAPTURE_FORMAT, Recording

__all__ = ["Capture", "CaptureAssembler", "Gap", "Level", "accel_g", "accel_ms2", "clipped_mask",
           "estimate_rate", "timing_steps", "clock_steps", "record", "write_capture",
           "CAPTURE_SUFFIXES", "MG_PER_DIGIT", "STANDARD_GRAVITY", "SENSOR", "AXES",
           "MAX_RECORD_S"]

STANDARD_GRAVITY = 9.80665  # m/s² per g (CGPM 1901)
MG_PER_DIGIT = {2: 1, 4: 2, 8: 4, 16: 12}  # LIS3DH high-resolution mode (12 bits)
_SHIFT = 4  # 12 bits, left-justified in 16
_LOW, _HIGH = -(1 << 11), (1 << 11) - 1  # the 12-bit limits: a sample there may be clipped
SENSOR = "LIS3DH"
AXES = ("x", "y", "z")
UNITS = "m/s^2"
CAPTURE_SUFFIXES = (".wav", ".npz", ".csv")
MAX_RECORD_S = 3600.0  # an hour: 4.8 M frames, 116 MB in memory as float64
OUTLIER_DEVIATIONS = 5.0  # blocks this many robust deviations off the rate line are left out
# A block's clock is at most a sample period (and the pen's read latency) after its last sample:
# a step of more than this many periods between two blocks is a late read or unflagged loss.
STEP_PERIODS = 3.0
_EDGE_BLOCKS = 8  # blocks on either side of an overrun that measure the samples it lost
LEVEL_WINDOW_S = 0.25  # the level meter looks at this much of the newest samples
_MAX_COMMENT_CHARS = 2000  # libsndfile reads back a WAV comment of at most 2048 bytes
_POLL_S = 0.1  # how long record() waits for a block before it looks at the stop flag again
_STALL_S = 2.0  # no block for this long (or the client's timeout, if longer): the pen stopped


class Gap(NamedTuple):
    """Samples missing from a capture.

    Attributes:
        at_s: where they are missing, in seconds from the capture's first sample.
        samples_lost: how many samples (for an overrun: measured from the pen's clock, to
            the nearest sample; 0 when the clock shows none missing though the FIFO overran).
        kind: ``"dropped"`` (blocks the pen or this host could not pass on: exact) or
            ``"overrun"`` (lost inside the sensor when its FIFO overran, flagged by the pen or
            seen only from its clock).
    """

    at_s: float
    samples_lost: int
    kind: str


class Level(NamedTuple):
    """The newest :data:`LEVEL_WINDOW_S` of a capture, per axis (x, y, z), in g.

    Attributes:
        rms_g: RMS about the mean (vibration; the mean is mostly gravity).
        peak_g: largest magnitude (what clips at the range).
        clipped: samples at the sensor's limits so far in the whole capture.
    """

    rms_g: tuple[float, float, float]
    peak_g: tuple[float, float, float]
    clipped: tuple[int, int, int]


def _check_range(range_g: int) -> int:
    if isinstance(range_g, bool) or range_g not in MG_PER_DIGIT:
        raise ParameterError("range_g", f"must be one of "
                                        f"{', '.join(map(str, MG_PER_DIGIT))} g, got {range_g!r}")
    return int(range_g)


def accel_g(raw: np.ndarray, range_g: int) -> np.ndarray:
    """Acceleration in g of LIS3DH samples as the sensor gives them (int16, left-justified,
    high-resolution mode).

    Args:
        raw: int16 samples, any shape.
        range_g: the full-scale range they were taken at: 2, 4, 8 or 16 g.

    Raises:
        ParameterError: another range.

    >>> accel_g(np.array([16, -32768, 32752], dtype=np.int16), 2).tolist()
    [0.001, -2.048, 2.047]
    """
    scale = MG_PER_DIGIT[_check_range(range_g)] / 1000
    return np.right_shift(np.asarray(raw, dtype=np.int16), _SHIFT) * scale


def accel_ms2(raw: np.ndarray, range_g: int) -> np.ndarray:
    """Acceleration in m/s² of LIS3DH samples (see :func:`accel_g`; 1 g = 9.80665 m/s²).

    >>> accel_ms2(np.array([1000 << 4], dtype=np.int16), 4).tolist()
    [19.6133]
    """
    return accel_g(raw, range_g) * STANDARD_GRAVITY


def clipped_mask(raw: np.ndarray) -> np.ndarray:
    """Which samples sit at either end of the 12-bit range (the sensor may have clipped them).

    >>> clipped_mask(np.array([0, 2047 << 4, -2048 << 4], dtype=np.int16)).tolist()
    [False, True, True]
    """
    digits = np.right_shift(np.asarray(raw, dtype=np.int16), _SHIFT)
    return (digits <= _LOW) | (digits >= _HIGH)


def _labels(segment: np.ndarray | None, count: int) -> np.ndarray:
    """Segment labels as 0, 1, 2 … in order of first appearance."""
    if segment is None:
        return np.zeros(count, dtype=np.int64)
    return np.unique(np.asarray(segment), return_inverse=True)[1].reshape(-1)


def _rough_period(x: np.ndarray, y: np.ndarray, seg: np.ndarray) -> float:
    """µs per sample: the median slope over spans of a few blocks within one segment (robust
    to the occasional step), or NaN."""
    for span in (8, 4, 2, 1):
        if len(x) > span:
            dx, dy = x[span:] - x[:-span], y[span:] - y[:-span]
            usable = (seg[span:] == seg[:-span]) & (dx > 0)
            if usable.any():
                return float(np.median(dy[usable] / dx[usable]))
    return math.nan


def timing_steps(last_index: np.ndarray, t_us: np.ndarray, segment: np.ndarray | None = None
                 ) -> np.ndarray:
    """Where the pen's clock steps against the sample index between two blocks of a segment by
    more than :data:`STEP_PERIODS` sample periods: a late read, or samples lost with no
    overrun flag.

    Returns:
        One bool per block: True where a step comes just before it.
    """
    x = np.asarray(last_index, dtype=np.float64)
    y = np.asarray(t_us, dtype=np.float64)
    seg = _labels(segment, len(x))
    steps = np.zeros(len(x), dtype=bool)
    period = _rough_period(x, y, seg)
    if len(x) < 3 or not period > 0:
        return steps
    residual = y - period * x
    steps[1:] = (seg[1:] == seg[:-1]) & (np.abs(np.diff(residual)) > STEP_PERIODS * period)
    return steps


def clock_steps(last_index: np.ndarray, t_us: np.ndarray, segment: np.ndarray,
                period_us: float) -> list[tuple[int, float]]:
    """The lasting steps of the pen's clock against the sample index: where it moved on by more
    than :data:`STEP_PERIODS` sample periods beyond the samples received and stayed ahead (a
    single late read comes back at the next block). Samples were lost there with no overrun
    flag.

    Args:
        last_index, t_us, segment: as for :func:`estimate_rate`.
        period_us: the sample period, in µs.

    Returns:
        (block at which the step comes, samples it stands for) for each.
    """
    x = np.asarray(last_index, dtype=np.float64)
    y = np.asarray(t_us, dtype=np.float64)
    seg = _labels(segment, len(x))
    steps = timing_steps(x, y, seg)
    if not steps.any():
        return []
    residual = y - period_us * x
    # Runs of blocks between steps and segment changes; a step counts when the run after it
    # (two blocks at least: one late read makes a run of one) stays above the one before.
    cuts = steps.copy()
    cuts[1:] |= seg[1:] != seg[:-1]
    bounds = [*np.flatnonzero(cuts), len(x)]
    found = []
    for before_start, start, end in zip([0, *bounds[:-2]], bounds[:-1], bounds[1:], strict=True):
        if not steps[start] or end - start < 2:
            continue
        before = residual[max(before_start, start - 4):start]
        lost = (np.median(residual[start:min(end, start + 4)]) - np.median(before)) / period_us
        if lost > STEP_PERIODS:
            found.append((int(start), float(lost)))
    return found


def estimate_rate(last_index: np.ndarray, t_us: np.ndarray, segment: np.ndarray | None = None
                  ) -> tuple[float, float, int]:
    """The sample rate from blocks' timestamps: a least-squares line of ``t_us`` against the
    index of each block's last sample, one intercept per segment, one slope.

    A segment is also cut where the clock steps (:func:`timing_steps`): a step shifts the line
    and would bend its slope, while a cut only costs a little precision. Blocks more than
    :data:`OUTLIER_DEVIATIONS` robust deviations (1.4826 × the median absolute residual) off a
    first fit are left out of the second.

    Args:
        last_index: index of each block's last sample (unwrapped).
        t_us: the pen's clock in µs when each block was read (unwrapped).
        segment: for each block, the stretch it belongs to (stretches between overruns, whose
            lost samples are only estimated); None: one stretch.

    Returns:
        (rate in Hz, its standard error in Hz, blocks used); NaN for both when fewer than two
        blocks more than segments remain.

    >>> index = np.arange(1, 11) * 32 - 1
    >>> rate, sd, used = estimate_rate(index, index * 1e6 / 1344 + 500)
    >>> round(rate, 6), used
    (1344.0, 10)
    """
    x = np.asarray(last_index, dtype=np.float64)
    y = np.asarray(t_us, dtype=np.float64)
    seg = _labels(segment, len(x))
    if len(x):
        cut = timing_steps(x, y, seg)
        cut[1:] |= seg[1:] != seg[:-1]
        seg = np.cumsum(cut) - int(cut[0])
    keep = np.ones(len(x), dtype=bool)
    fit = _fit(x, y, seg, keep)
    if fit is None:
        return math.nan, math.nan, 0
    residuals = fit[2]
    deviation = 1.4826 * float(np.median(np.abs(residuals[keep] - np.median(residuals[keep]))))
    if deviation > 0:
        keep = np.abs(residuals - np.median(residuals[keep])) <= OUTLIER_DEVIATIONS * deviation
        fit = _fit(x, y, seg, keep) or fit
    slope, slope_se, _, used = fit
    if not slope > 0:
        return math.nan, math.nan, used
    return 1e6 / slope, 1e6 * slope_se / slope**2, used


def _fit(x: np.ndarray, y: np.ndarray, seg: np.ndarray, keep: np.ndarray):
    """(slope, its standard error, residuals of every point, points used) of the common-slope
    fit over the ``keep`` points, or None when too few points are left."""
    xs, ys, ss = x[keep], y[keep], seg[keep]
    groups = int(ss.max()) + 1 if len(ss) else 0
    counts = np.bincount(ss, minlength=groups).astype(np.float64)
    freedom = len(xs) - np.count_nonzero(counts) - 1
    if freedom < 1:
        return None
    with np.errstate(invalid="ignore", divide="ignore"):
        x_mean = np.bincount(ss, xs, groups) / counts
        y_mean = np.bincount(ss, ys, groups) / counts
    dx, dy = xs - x_mean[ss], ys - y_mean[ss]
    sxx = float(dx @ dx)
    if sxx <= 0:
        return None
    slope = float(dx @ dy) / sxx
    kept_residuals = dy - slope * dx
    slope_se = math.sqrt(float(kept_residuals @ kept_residuals) / freedom / sxx)
    # Every point's residual from its own segment's line (a left-out point's segment mean is
    # that of the points kept in it).
    all_x_mean = np.zeros(int(seg.max()) + 1)
    all_y_mean = np.zeros(int(seg.max()) + 1)
    all_x_mean[:groups], all_y_mean[:groups] = np.nan_to_num(x_mean), np.nan_to_num(y_mean)
    residuals = (y - all_y_mean[seg]) - slope * (x - all_x_mean[seg])
    return slope, slope_se, residuals, len(xs)


@dataclass(frozen=True, eq=False)
class Capture:
    """An accelerometer capture on the sensor's grid.

    Attributes:
        samples: float64 of shape (frames, 3), x, y, z in m/s² (gravity included); NaN where
            samples are missing (:attr:`gaps`).
        rate_hz: the sensor's rate estimated from the pen's clock, in Hz.
        rate_sd_hz: its standard error in Hz (NaN with fewer than three blocks).
        gaps: where samples are missing, in order.
        clipped: samples at the 12-bit limits per axis (x, y, z).
        blocks: SAMPLES blocks received.
        range_g: the full-scale range in g.
        nominal_rate_hz: the rate the sensor was set to.
        interrupted: stopped early (Ctrl-C, a stop request) rather than after the time asked.
        provenance: what the files carry: sensor, range, rates, pen, firmware, protocol, port,
            host, start (UTC), duration, gaps, clipping (JSON-ready).
        notes: things the user should know (the pen did not confirm the stop, blocks the host
            dropped).
    """

    samples: np.ndarray
    rate_hz: float
    rate_sd_hz: float
    gaps: list[Gap]
    clipped: tuple[int, int, int]
    blocks: int
    range_g: int
    nominal_rate_hz: float
    interrupted: bool = False
    provenance: dict = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    @property
    def frames(self) -> int:
        """Samples per axis, gaps included."""
        return int(self.samples.shape[0])

    @property
    def duration_s(self) -> float:
        """Length in seconds at :attr:`rate_hz`."""
        return self.frames / self.rate_hz if self.frames else 0.0

    @property
    def samples_lost(self) -> int:
        """Samples missing in all the gaps."""
        return sum(gap.samples_lost for gap in self.gaps)

    def to_recording(self, source: str = "capture") -> Recording:
        """The capture as a :class:`~realpen.io.recording.Recording` (m/s², gaps as 0, as the
        files hold them), ready for :func:`realpen.analyze` or a profile build."""
        return Recording(np.nan_to_num(self.samples, nan=0.0), self.rate_hz, AXES, units=UNITS,
                         source=source)

    def __repr__(self) -> str:
        return (f"Capture({self.frames} frames at {self.rate_hz:.2f} ± {self.rate_sd_hz:.2f} Hz "
                f"({self.duration_s:.2f} s), ±{self.range_g} g, {len(self.gaps)} gaps, "
                f"clipped {list(self.clipped)})")


def _unwrap(previous_raw: int, previous: int, value: int) -> int:
    """``value`` (u32 that wraps) on the unwrapped scale of ``previous`` (its raw
    ``previous_raw``): the step between them taken as the nearer way round."""
    step = (value - previous_raw) & 0xFFFFFFFF
    if step >= 1 << 31:
        step -= 1 << 32
    return previous + step


class _Placed(NamedTuple):
    first: int  # grid offset of the first sample, as the pen counts
    raw: np.ndarray
    range_g: int
    flagged: bool  # came with SAMPLES_OVERRUN
    last: int  # index of the last sample (for the rate)
    t_us: int  # unwrapped
    segment: int  # stretch between flagged overruns


class CaptureAssembler:
    """Builds a :class:`Capture` from SAMPLES blocks and the pen's capture events, in order of
    arrival; gives a live level and rate estimate while it runs.

    Args:
        range_g: the range asked for, in g (each block is scaled by its own).
        nominal_rate_hz: the rate the sensor was set to, in Hz.
        info: the pen's :class:`~realpen.device.client.PenInfo` (for the provenance).
        port: the pen's port (for the provenance).
    """

    def __init__(self, range_g: int = 2, nominal_rate_hz: float = p.CAPTURE_RATE, *,
                 info: PenInfo | None = None, port: str | None = None):
        self.range_g = _check_range(range_g)
        require_number("nominal_rate_hz", nominal_rate_hz, 0, inclusive=False)
        self.nominal_rate_hz = float(nominal_rate_hz)
        self.info, self.port = info, port
        self.started_at = datetime.now(UTC)
        self.blocks = 0
        self.blocks_ignored = 0  # wholly repeated blocks, or an index far beyond any gap
        self._max_jump = round(MAX_RECORD_S * self.nominal_rate_hz)
        self.pen_overruns = 0  # the pen's count (EV_OVERRUN)
        self.flagged_overruns = 0  # blocks flagged SAMPLES_OVERRUN
        self.pen_dropped = 0  # blocks the pen could not send (EV_CAPTURE_DROPPED)
        self.received = 0  # samples placed on the grid
        self.clipped = np.zeros(3, dtype=np.int64)
        # One entry per block placed, appended whole (a Ctrl-C between two statements cannot
        # leave the parts of a block out of step): grid offset of its first sample, its raw
        # samples, range in g, overrun flag, index of its last sample, unwrapped t_us, segment.
        self._placed: list[_Placed] = []
        self._gaps: list[tuple[int, int, str]] = []  # (grid offset, samples, kind)
        self._next = 0  # grid offset of the next expected sample
        self._next_raw = 0
        self._t_raw: int | None = None
        self._t = 0
        self._segment = 0
        self._estimate: tuple[float, float, int] | None = None
        self._estimated_blocks = 0  # blocks the cached estimate was made from
        self._recent: deque[np.ndarray] = deque()
        self._recent_frames = 0

    # -- input -------------------------------------------------------------------------------

    def feed(self, item: SampleBlock | PenEvent) -> None:
        """Take the next block or event (other events are ignored)."""
        if isinstance(item, SampleBlock):
            self.feed_block(item)
        else:
            self.feed_event(item)

    def feed_event(self, event: PenEvent) -> None:
        """Take the pen's count of overruns or of blocks it could not send."""
        if event.kind == p.EV_OVERRUN:
            self.pen_overruns = max(self.pen_overruns, int(event.value))
        elif event.kind == p.EV_CAPTURE_DROPPED:
            self.pen_dropped = max(self.pen_dropped, int(event.value))

    def feed_block(self, block: SampleBlock) -> None:
        """Place one SAMPLES block on the grid (in the order the pen sent them)."""
        first = _unwrap(self._next_raw, self._next, block.first)
        raw = block.raw
        if first - self._next > self._max_jump:  # no pen loses that much and goes on: garbage
            self.blocks_ignored += 1
            return
        if block.overrun:
            self.flagged_overruns += 1
        if first > self._next:
            kind = "overrun" if block.overrun else "dropped"
            self._gaps.append((self._next, first - self._next, kind))
        elif block.overrun:  # flagged with no samples counted lost: say where it happened
            self._gaps.append((self._next, 0, "overrun"))
        if block.overrun and self.blocks:
            self._segment += 1  # the lost count is an estimate: a new intercept from here
        if first < self._next:  # a repeat of samples already placed: keep only the new ones
            skip = self._next - first
            if skip >= len(raw):
                self.blocks_ignored += 1
                return
            raw, first = raw[skip:], self._next
        self.blocks += 1
        last = first + len(raw) - 1
        t = block.t_us if self._t_raw is None else _unwrap(self._t_raw, self._t, block.t_us)
        range_g = block.range_g if block.range_g in MG_PER_DIGIT else self.range_g
        self._placed.append(_Placed(first, raw, range_g, block.overrun, last, t, self._segment))
        self._t, self._t_raw = t, block.t_us
        self.clipped += clipped_mask(raw).sum(axis=0)
        self.received += len(raw)
        self._next = first + len(raw)
        self._next_raw = (block.first + (len(block.raw))) & 0xFFFFFFFF
        self._remember(accel_g(raw, range_g))

    def _remember(self, values_g: np.ndarray) -> None:
        self._recent.append(values_g)
        self._recent_frames += len(values_g)
        window = max(1, round(LEVEL_WINDOW_S * self.nominal_rate_hz))
        while self._recent_frames - len(self._recent[0]) >= window:
            self._recent_frames -= len(self._recent.popleft())

    # -- live view ---------------------------------------------------------------------------

    @property
    def overruns(self) -> int:
        """The sensor FIFO's overruns so far (the pen's count, or the flagged blocks if more
        of those came)."""
        return max(self.pen_overruns, self.flagged_overruns)

    @property
    def frames(self) -> int:
        """Samples per axis so far on the grid, gaps included."""
        return self._next

    @staticmethod
    def _fit_arrays(placed: list[_Placed]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(index of each block's last sample, its t_us, its segment) as arrays."""
        return (np.array([b.last for b in placed], dtype=np.float64),
                np.array([b.t_us for b in placed], dtype=np.float64),
                np.array([b.segment for b in placed], dtype=np.int64))

    def rate(self, fresh: bool = False) -> tuple[float, float]:
        """(rate in Hz, standard error in Hz) from the blocks so far; NaN until there are
        three.

        Args:
            fresh: from every block; otherwise the estimate is made again only once the
                blocks grew by 2 % since the last one (a long capture would spend its time
                refitting at every block).
        """
        count = len(self._placed)
        if self._estimate is None or (count != self._estimated_blocks and (
                fresh or count >= self._estimated_blocks * 1.02 + 1)):
            self._estimate = estimate_rate(*self._fit_arrays(self._placed[:count]))
            self._estimated_blocks = count
        rate, sd, _ = self._estimate
        return rate, sd

    @property
    def rate_or_nominal(self) -> float:
        """The estimated rate, or the nominal one while there is none (Hz)."""
        rate, _ = self.rate()
        return rate if math.isfinite(rate) else self.nominal_rate_hz

    @property
    def duration_s(self) -> float:
        """Seconds on the grid so far (gaps included), at the estimated rate."""
        return self._next / self.rate_or_nominal

    def level(self) -> Level:
        """The level meter: RMS and peak of the newest :data:`LEVEL_WINDOW_S` per axis, in g,
        and the clipped samples so far."""
        clipped = tuple(int(c) for c in self.clipped)
        if not self._recent:
            return Level((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), clipped)
        values = np.concatenate(list(self._recent))
        rms = np.sqrt(np.mean((values - values.mean(axis=0)) ** 2, axis=0))
        peak = np.max(np.abs(values), axis=0)
        return Level(tuple(map(float, rms)), tuple(map(float, peak)), clipped)

    def _placement(self, rate: float, placed: list[_Placed]
                   ) -> tuple[np.ndarray, list[tuple[int, int, str]], int]:
        """Where each block's samples go on the grid, with the pen's clock correcting its
        estimate of the samples an overrun lost, and finding losses it did not flag.

        From an overrun (and from a lasting step of the clock, :func:`clock_steps`) on, the
        blocks' times lie off the line of the blocks before by the samples lost: measured
        from the medians of the offsets from the line of up to :data:`_EDGE_BLOCKS` blocks
        on either side (near each other, so that an error in the rate hardly matters), to
        the nearest sample, it replaces the pen's estimate. Dropped blocks are exact and
        move nothing.

        Returns:
            (grid offset of each block, gaps as (offset, samples, kind), how many of the
            overrun gaps no flag announced).
        """
        pen_offsets = np.array([b.first for b in placed], dtype=np.int64)
        if not placed:
            return pen_offsets, [], 0
        x, y, seg = self._fit_arrays(placed)
        period = 1e6 / rate
        residual = y - period * x
        new_stretch = np.zeros(len(x), dtype=bool)
        new_stretch[1:] = seg[1:] != seg[:-1]
        unflagged = np.zeros(len(x), dtype=bool)
        for block, _ in clock_steps(x, y, seg, period):
            if new_stretch[block - 1]:
                continue  # the step out of an overrun's own block: part of that overrun
            unflagged[block] = not new_stretch[block]
            new_stretch[block] = True
        stretch = np.cumsum(new_stretch)
        firsts = [int(i) for i in np.flatnonzero(new_stretch)]
        corrections = [0]
        for k, start in enumerate(firsts):
            before = firsts[k - 1] if k else 0
            end = firsts[k + 1] if k + 1 < len(firsts) else len(x)
            # Not the stretch's first block: a full FIFO keeps taking samples until the pen's
            # read begins, so its last sample may be newer than its time says.
            first = start + 1 if end - start > 1 else start
            step = (np.median(residual[first:min(end, first + _EDGE_BLOCKS)])
                    - np.median(residual[max(before, start - _EDGE_BLOCKS):start])) / period
            corrections.append(round(float(step)))
        shifts = np.cumsum(corrections)
        starts = np.empty_like(pen_offsets)
        gaps: list[tuple[int, int, str]] = []
        end = shift = found = 0
        for block, piece in enumerate(placed):
            pen_offset, raw, flagged = piece.first, piece.raw, piece.flagged
            if new_stretch[block]:
                # The grid never runs backwards: an overestimated loss moves the stretch back
                # to no loss at all.
                shift = max(int(shifts[stretch[block]]), end - int(pen_offset))
            start = int(pen_offset) + shift
            lost = start - end
            if flagged or (unflagged[block] and lost > 0):
                gaps.append((end, lost, "overrun"))
                found += bool(unflagged[block] and not flagged)
            elif lost > 0:
                gaps.append((end, lost, "dropped"))
            starts[block] = start
            end = start + len(raw)
        return starts, gaps, found

    def gaps(self) -> list[Gap]:
        """The gaps so far as the pen counts them, placed at the estimated rate (the
        capture's own, :meth:`result`, are corrected from the pen's clock)."""
        rate = self.rate_or_nominal
        return [Gap(offset / rate, count, kind) for offset, count, kind in self._gaps]

    # -- result ------------------------------------------------------------------------------

    def result(self, *, interrupted: bool = False, host_dropped: int = 0,
               notes: tuple[str, ...] = ()) -> Capture:
        """The capture so far.

        Args:
            interrupted: it was stopped before the time asked for (for the provenance).
            host_dropped: blocks this host dropped (:attr:`PenClient.blocks_dropped`).
            notes: more to tell the user.
        """
        rate, sd = self.rate(fresh=True)
        if not math.isfinite(rate):  # too few blocks to tell: the nominal rate, unknown error
            rate, sd = self.nominal_rate_hz, math.nan
        placed = self._placed[:len(self._placed)]
        starts, gap_list, unflagged = self._placement(rate, placed)
        frames = int(starts[-1] + len(placed[-1].raw)) if placed else 0
        samples = np.full((frames, 3), np.nan)
        for start, piece in zip(starts, placed, strict=True):
            samples[start:start + len(piece.raw)] = accel_ms2(piece.raw, piece.range_g)
        gaps = [Gap(offset / rate, count, kind) for offset, count, kind in gap_list]
        notes = tuple(notes)
        if unflagged:
            notes += (f"{unflagged} of the overrun gaps had no overrun flag: the pen's clock "
                      f"showed the samples missing",)
        if host_dropped:
            notes += (f"this host dropped {host_dropped} block{'s' if host_dropped != 1 else ''} "
                      f"it could not read in time (shown as gaps)",)
        capture = Capture(samples, rate, sd, gaps, tuple(int(c) for c in self.clipped),
                          self.blocks, self.range_g, self.nominal_rate_hz, interrupted,
                          notes=notes)
        provenance = self._provenance(capture, host_dropped)
        return Capture(samples, rate, sd, gaps, capture.clipped, self.blocks, self.range_g,
                       self.nominal_rate_hz, interrupted, provenance, notes)

    def _provenance(self, capture: Capture, host_dropped: int) -> dict:
        from realpen._version import __version__

        info = self.info
        rate_sd = capture.rate_sd_hz
        return {
            "format": CAPTURE_FORMAT,
            "sensor": SENSOR,
            "range_g": self.range_g,
            "units": UNITS,
            "axes": list(AXES),
            "rate_hz": capture.rate_hz,
            "rate_sd_hz": None if not math.isfinite(rate_sd) else rate_sd,
            "rate_from": "least squares of the pen's block timestamps",
            "nominal_rate_hz": self.nominal_rate_hz,
            "pen": info.name if info else None,
            "firmware": info.firmware_version if info else None,
            "protocol": info.protocol if info else p.PROTOCOL_VERSION,
            "port": self.port,
            "host": platform.node() or None,
            "software": f"realpen {__version__}",
            "started_at": self.started_at.isoformat(timespec="seconds"),
            "duration_s": round(capture.duration_s, 6),
            "frames": capture.frames,
            "blocks": self.blocks,
            "stopped": "interrupted" if capture.interrupted else "complete",
            "samples_lost": capture.samples_lost,
            "gaps": [[round(g.at_s, 6), g.samples_lost, g.kind] for g in capture.gaps],
            "gap_values": "0 in files (NaN in memory)",
            "overruns": self.overruns,
            "blocks_dropped_by_pen": self.pen_dropped,
            "blocks_dropped_by_host": host_dropped,
            "clipped": dict(zip(AXES, capture.clipped, strict=True)),
        }


# --- files -------------------------------------------------------------------------------------

def write_capture(capture: Capture, path: str | Path) -> Path:
    """Write a capture atomically as WAV, NPZ or CSV (by the suffix), in m/s², gaps as 0.

    - ``.wav``: float32, one channel per axis, at the nearest whole Hz in the header; the exact
      rate and the provenance as JSON in the file's comment, which
      :func:`realpen.io.recording.load_recording` (and ``realpen profile build``) read.
    - ``.npz``: ``samples`` (float32), ``rate`` (float64, exact), ``axes``, ``units`` and
      ``provenance`` (JSON text).
    - ``.csv``: ``time_s,x,y,z``, the time from the exact rate (ns resolution): the loaders take
      the rate from it. CSV has no place for the provenance.

    Returns:
        The path written.

    Raises:
        RealPenError: another suffix, an empty capture, or a place that takes no file (one line
            naming ``path``).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in CAPTURE_SUFFIXES:
        raise fail(path, f"a capture is written as {', '.join(CAPTURE_SUFFIXES[:-1])} or "
                         f"{CAPTURE_SUFFIXES[-1]}; give a name ending in one of them")
    if capture.frames == 0:
        raise fail(path, "the capture holds no samples; nothing written")
    samples = np.nan_to_num(capture.samples, nan=0.0)
    with atomic_path(path) as tmp:
        if suffix == ".wav":
            _write_wav(tmp, samples, capture)
        elif suffix == ".npz":
            with open(tmp, "wb") as handle:
                np.savez_compressed(handle, samples=samples.astype(np.float32),
                                    rate=np.float64(capture.rate_hz), axes=np.array(AXES),
                                    units=np.array(UNITS),
                                    provenance=np.array(json.dumps(capture.provenance)))
        else:
            times = np.arange(capture.frames) / capture.rate_hz
            with open(tmp, "w", encoding="utf-8", newline="\n") as handle:
                np.savetxt(handle, np.column_stack([times, samples]),
                           fmt=("%.9f", "%.7g", "%.7g", "%.7g"), delimiter=",",
                           header="time_s," + ",".join(AXES), comments="")
    return path


def _wav_comment(provenance: dict) -> str:
    """The provenance as compact JSON short enough for a WAV comment: the list of gaps is cut
    (their count and total stay) when it would not fit."""
    data = dict(provenance)
    text = json.dumps(data, separators=(",", ":"))
    gaps = list(data.get("gaps", []))
    while len(text) > _MAX_COMMENT_CHARS and gaps:
        gaps = gaps[:len(gaps) // 2]
        data["gaps"] = gaps
        data["gaps_listed"] = f"{len(gaps)} of {len(provenance['gaps'])}"
        text = json.dumps(data, separators=(",", ":"))
    if len(text) > _MAX_COMMENT_CHARS:  # long names: keep what the loaders need
        text = json.dumps({key: provenance[key] for key in ("format", "sensor", "range_g",
                                                           "units", "rate_hz", "rate_sd_hz",
                                                           "nominal_rate_hz")},
                          separators=(",", ":"))
    return text


def _write_wav(tmp: Path, samples: np.ndarray, capture: Capture) -> None:
    import soundfile as sf

    with sf.SoundFile(tmp, "w", samplerate=round(capture.rate_hz), channels=samples.shape[1],
                      subtype="FLOAT", format="WAV") as handle:
        handle.comment = _wav_comment(capture.provenance)
        handle.write(samples.astype(np.float32))


# --- a capture from a pen ----------------------------------------------------------------------

def record(client: PenClient, seconds: float, *, range_g: int = 2,
           on_block: Callable[[SampleBlock, CaptureAssembler], None] | None = None,
           stop_event: threading.Event | None = None) -> Capture:
    """Capture the pen's accelerometer for ``seconds`` at 1344 Hz.

    Starts the capture, places the blocks as they come, and stops it when ``seconds`` of
    samples (at the estimated rate, gaps included) are there, ``stop_event`` is set, or Ctrl-C
    (KeyboardInterrupt) comes: what was captured until then is kept and returned
    (:attr:`Capture.interrupted`). The capture is stopped in every case, and the blocks the pen
    sent before its stop are all placed.

    Args:
        client: a client of the pen (it says HELLO first when it has not yet).
        seconds: how long, 0 < seconds ≤ :data:`MAX_RECORD_S`.
        range_g: full-scale range in g: 2, 4, 8 or 16.
        on_block: called as ``on_block(block, assembler)`` after each block is placed (a live
            display reads :meth:`CaptureAssembler.level` and :meth:`CaptureAssembler.rate`).
        stop_event: set it (from another thread) to stop early.

    Returns:
        The :class:`Capture`.

    Raises:
        ParameterError: ``seconds`` or ``range_g`` out of range.
        DeviceError: the pen has no accelerometer, refused the capture, sent nothing for
            2 s, or the link went away.
    """
    require_number("seconds", seconds, 0, MAX_RECORD_S, inclusive=False)
    _check_range(range_g)
    info = client.info or client.hello()
    assembler = CaptureAssembler(range_g, p.CAPTURE_RATE, info=info, port=client.name)
    stall_s = max(_STALL_S, client.timeout)
    interrupted = False
    notes: list[str] = []
    capturing = False
    try:
        capturing = True  # from the request on: the pen may be capturing though its ACK is lost
        client.start_capture(range_g, p.CAPTURE_RATE)
        last_block = time.monotonic()
        while True:
            if stop_event is not None and stop_event.is_set():
                interrupted = True
                break
            block = client.read_samples(_POLL_S)
            for event in client.events():
                assembler.feed_event(event)
            if block is None:
                if time.monotonic() - last_block > stall_s:
                    raise DeviceError(f"{client.name}: no samples from the pen for "
                                      f"{stall_s:g} s (is its accelerometer connected?)")
                continue
            last_block = time.monotonic()
            assembler.feed_block(block)
            if on_block is not None:
                on_block(block, assembler)
            if assembler.duration_s >= seconds:
                break
    except KeyboardInterrupt:
        interrupted = True
    except BaseException:
        if capturing:
            _stop_quietly(client)
        raise
    if capturing:
        try:
            client.stop_capture()
        except DeviceError as error:
            notes.append(f"the pen did not confirm the end of the capture ({error}); the last "
                         f"blocks may be missing")
        _drain(client, assembler)
    return assembler.result(interrupted=interrupted, host_dropped=client.blocks_dropped,
                            notes=tuple(notes))


def _drain(client: PenClient, assembler: CaptureAssembler) -> None:
    """Place the blocks and events still queued (after the stop: all the capture's)."""
    try:
        while (block := client.read_samples(0)) is not None:
            assembler.feed_block(block)
    except DeviceError:  # the link went away after the stop: what arrived is placed
        pass
    for event in client.events():
        assembler.feed_event(event)


def _stop_quietly(client: PenClient) -> None:
    """Ask the pen to stop capturing after a failure (which is what gets reported)."""
    try:
        client.stop_capture()
    except DeviceError:
        pass
