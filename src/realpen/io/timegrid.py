"""Timestamped samples with dropped samples put on an even time grid (phone-sensor CSVs).

A recording CSV with a time column gives its rate from the median step between timestamps
(:mod:`realpen.io.recording`). Jitter of a step's length is interpolated away as the file is
read; a *gap* — a step over :data:`~realpen.io.recording.GAP_FACTOR` times the median, samples
that are missing — is refused, because filling it invents signal. A phone's accelerometer
drops samples as a matter of course (the operating system delivers sensor events when it
can), so for such a file the caller may ask for the gaps to be filled explicitly:
:func:`place_on_grid` interpolates the samples onto an even grid (at the median rate or at a
given rate), counts the grid points that fall where the file had no sample, and refuses the
file when they are more than a stated share of the whole (:data:`DEFAULT_MAX_INTERPOLATED_PCT`,
5 %, by default). The :class:`GridReport` says what was done.

Interpolation is a cubic spline through the file's samples, as for jitter: it keeps tones up
to a third of the rate within a few per cent, and bridges a single missing sample best. Across
a longer gap (over :data:`SPLINE_GAP_STEPS` steps) a spline swings far beyond the signal (on
tones at a third of the rate, three times its RMS across a 12-sample gap), so there the grid
holds a straight line between the samples on either side: it invents no oscillation, only a
slow ramp that the analysis's 30 Hz high-pass mostly removes. Either way the gap holds no
vibration that was there: the share interpolated is what to watch, and the longest gap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realpen.checks import MAX_RATE_HZ, MIN_RATE_HZ, require_number, require_rate
from realpen.errors import ParameterError, fail
from realpen.io.limits import check_signal

__all__ = ["GridReport", "place_on_grid", "gap_refusal", "grid_rate_choice",
           "missing_samples", "DEFAULT_MAX_INTERPOLATED_PCT", "MIN_GRID_RATE_RATIO",
           "SPLINE_GAP_STEPS"]

DEFAULT_MAX_INTERPOLATED_PCT = 5.0
"""The largest share (per cent) of a grid's samples that may be interpolated where the file had
none, unless the caller says otherwise."""

SPLINE_GAP_STEPS = 2.0
"""Steps (of the median step) up to which the spline fills a gap; longer gaps are bridged by a
straight line (see the module doc)."""

MIN_GRID_RATE_RATIO = 0.97
"""A given grid rate may be at most 3 % below the file's median rate (a phone's nominal rate
often is, the sensor's clock being a few per cent off): interpolating to a lower rate would
fold the top of the band back without an anti-aliasing filter. Lower rates come from
resampling afterwards (``analysis_rate``)."""


@dataclass(frozen=True)
class GridReport:
    """What putting a recording on an even grid did.

    Attributes:
        rate: the grid's rate in Hz.
        median_rate: the file's rate in Hz from its median time step.
        rows: samples in the file.
        frames: samples on the grid.
        missing: samples the file lacks in its gaps (a step of k median steps lacks k − 1),
            interpolated on the grid.
        longest_gap_s: the longest step between two of the file's samples, in s.
        longest_gap_after_s: where it starts, in s from the first sample.
    """

    rate: float
    median_rate: float
    rows: int
    frames: int
    missing: int
    longest_gap_s: float
    longest_gap_after_s: float

    @property
    def interpolated_pct(self) -> float:
        """The share of the recording's time where samples were missing, in per cent."""
        return 100.0 * self.missing / max(1, self.rows + self.missing)

    def __str__(self) -> str:
        return (f"put on an even grid at {self.rate:.6g} Hz (the file's median rate "
                f"{self.median_rate:.6g} Hz): {self.missing:,} missing sample(s) interpolated, "
                f"{self.interpolated_pct:.2f} % of {self.rows + self.missing:,}; the longest gap "
                f"{1000 * self.longest_gap_s:.1f} ms after {self.longest_gap_after_s:.3f} s")


def missing_samples(steps: np.ndarray, step: float) -> np.ndarray:
    """Samples missing in each step between timestamps (s), ``step`` (s) being the median."""
    return np.maximum(np.rint(steps / step) - 1, 0).astype(np.int64)


def grid_rate_choice(even_grid: bool | str | float | None) -> bool | float | None:
    """``even_grid`` as :func:`place_on_grid` takes it: None (off), True (the median rate) or
    a rate in Hz.

    Args:
        even_grid: False or None (off), True or ``"median"`` (the file's median rate), or a
            rate in Hz (:data:`~realpen.checks.MIN_RATE_HZ` to :data:`~realpen.checks.MAX_RATE_HZ`).

    Raises:
        ParameterError: (``even_grid``) anything else.
    """
    if even_grid is None or even_grid is False:
        return None
    if even_grid is True or (isinstance(even_grid, str) and even_grid.strip().lower() == "median"):
        return True
    if isinstance(even_grid, str):
        try:
            even_grid = float(even_grid)
        except ValueError:
            raise ParameterError("even_grid", f"must be 'median' or a rate in Hz, got "
                                              f"{even_grid[:40]!r}") from None
    require_rate("even_grid", even_grid)
    return float(even_grid)


def gap_refusal(source: object, time_name: str, gap_s: float, after_s: float,
                step_s: float) -> ParameterError:
    """The error for a gap in a time column when no even grid was asked for: it names the
    file, the gap and ``even_grid``, the option that fills gaps (the command line names its
    flag)."""
    return ParameterError("even_grid", f"needed: {source}: time column '{time_name}' has a gap "
                                       f"of {gap_s:.4g} s after {after_s:.4g} s (samples are "
                                       f"{step_s:.4g} s apart), so samples are missing; put "
                                       f"the recording on an even grid to interpolate them "
                                       f"(the share is reported, and limited), or analyse the "
                                       f"parts on either side separately")


def place_on_grid(times: np.ndarray, values: np.ndarray, *, rate: bool | float = True,
                  max_interpolated_pct: float = DEFAULT_MAX_INTERPOLATED_PCT,
                  source: object = "recording", time_name: str = "time"
                  ) -> tuple[np.ndarray, GridReport]:
    """Samples with timestamps, gaps included, interpolated onto an even grid.

    Args:
        times: the timestamps in s, shape (rows,), strictly increasing.
        values: the samples, shape (rows, axes).
        rate: True for the file's median rate, or a rate in Hz (at least
            :data:`MIN_GRID_RATE_RATIO` of the median rate).
        max_interpolated_pct: refuse the file when more than this share (per cent, 0–100) of
            its samples is missing.
        source, time_name: the file and its time column, for messages.

    Returns:
        (samples on the grid, shape (frames, axes); the :class:`GridReport`). The grid starts
        at the first timestamp and ends at or before the last.

    Raises:
        ParameterError: a bad ``max_interpolated_pct`` or ``rate`` (named so), or a rate below
            what the file's median rate allows.
        RealPenError: times that do not increase, a median rate outside what RealPen reads, or
            more missing than ``max_interpolated_pct`` (naming the file, the share and the
            limit).

    Example:
        >>> import numpy as np
        >>> times = np.delete(np.arange(1000) / 400, [100, 101, 102, 500])  # 4 dropped
        >>> samples, report = place_on_grid(times, np.sin(2 * np.pi * 50 * times)[:, None])
        >>> samples.shape, report.missing, round(report.interpolated_pct, 2)
        ((1000, 1), 4, 0.4)
    """
    require_number("max_interpolated_pct", max_interpolated_pct, minimum=0.0, maximum=100.0)
    times = np.asarray(times, dtype=np.float64)
    steps = np.diff(times)
    if len(steps) == 0 or not np.all(steps > 0):
        raise fail(source, f"time column '{time_name}' is not strictly increasing")
    step = float(np.median(steps))
    median_rate = 1.0 / step
    if not MIN_RATE_HZ <= median_rate <= MAX_RATE_HZ:
        raise fail(source, f"time column '{time_name}' gives a sampling rate of "
                           f"{median_rate:.4g} Hz, outside the {MIN_RATE_HZ:,}–{MAX_RATE_HZ:,} "
                           f"Hz RealPen reads (are the times in seconds?)")
    if rate is True:
        rate = median_rate
    else:
        require_rate("even_grid", rate)
    if rate < MIN_GRID_RATE_RATIO * median_rate:
        raise ParameterError("even_grid", f"{rate:g} Hz is below the {median_rate:.6g} Hz of "
                                          f"{source}'s time column; put it on the grid at its "
                                          f"own rate and resample afterwards (interpolating "
                                          f"to a lower rate would alias)")
    missing = missing_samples(steps, step)
    widest = int(np.argmax(steps))
    report = GridReport(float(rate), median_rate, len(times),
                        int(np.floor((times[-1] - times[0]) * rate + 1e-9)) + 1,
                        int(missing.sum()), float(steps[widest]),
                        float(times[widest] - times[0]))
    if report.interpolated_pct > max_interpolated_pct:
        raise fail(source, f"{report.interpolated_pct:.2f} % of the samples are missing "
                           f"({report.missing:,} of {report.rows + report.missing:,}; the "
                           f"longest gap {1000 * report.longest_gap_s:.1f} ms after "
                           f"{report.longest_gap_after_s:.3f} s), over the limit of "
                           f"{max_interpolated_pct:g} % that may be interpolated")
    check_signal(source, rate, report.frames, values.shape[1])  # before the grid is allocated
    grid = times[0] + np.arange(report.frames) / rate
    from scipy.interpolate import CubicSpline  # heavy to import: only for uneven sampling

    values = np.asarray(values, dtype=np.float64)
    placed = CubicSpline(times, values, axis=0)(grid)
    after = np.clip(np.searchsorted(times, grid, side="right"), 1, len(times) - 1)
    bridged = steps[after - 1] > SPLINE_GAP_STEPS * step
    if bridged.any():
        for axis in range(values.shape[1]):
            placed[bridged, axis] = np.interp(grid[bridged], times, values[:, axis])
    return placed, report
