"""A pen trajectory: the columnar form of stroke samples, checked, with the live page's speed.

A trajectory's columns and value ranges are those of the one stroke-sample definition,
:class:`realpen.io.strokes.StrokeSample` (``t`` s, ``x`` and ``y`` mm, ``pressure`` 0–1, tilt in
degrees); :class:`Trajectory` is its columnar form, and converts to and from a list of samples.
The sound (:mod:`realpen.sound.stroke`) and the tactile loop (:mod:`realpen.tactile.stroke`)
are both rendered along one.

Speed is the live page's (``SpeedMeter`` in ``live/static/pen.js``), event by event: the path
length travelled since the newest earlier event at least ``SPEED_WINDOW_MS`` (20 ms) before
this one, divided by the time between the two, in mm/s. While the stroke is younger than
20 ms the window reaches back to its first event, and it always spans at least one step. A row
with pressure 0 is the pen lifted: its speed is 0, and the next row with pressure > 0 is a
touch-down, where the page's meter restarts (speed 0: the pen has not slid yet). A single
step's distance would be mostly rounding on a touch screen, hence the window. (The page restarts
its meter only at pointer-down: if a pen reports pressure 0 in the middle of a stroke, the page
keeps measuring through it while this reading restarts. The gain there is 0 either way; only
the speed of the next 20 ms after it can differ.)
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from realpen.checks import MAX_DURATION_S, check_ms
from realpen.errors import ParameterError, fail
from realpen.io.csvtable import read_csv
from realpen.io.strokes import (
    POSITION_RANGE_MM,
    PRESSURE_RANGE,
    TILT_RANGE_DEG,
    TRAJECTORY_FIELDS,
    StrokeSample,
)

__all__ = ["Trajectory", "load_trajectory", "SPEED_WINDOW_MS", "TILT_FIELDS"]

SPEED_WINDOW_MS = 20.0  # the live page's speed window (SPEED_WINDOW_MS in live/static/pen.js)
TILT_FIELDS = ("tilt_x", "tilt_y")  # optional trajectory columns, degrees


@dataclass(frozen=True, repr=False, eq=False)
class Trajectory:
    """A pen trajectory: one row per pen event, the columnar form of
    :class:`~realpen.io.strokes.StrokeSample` rows.

    Attributes:
        t: time in s, strictly increasing.
        x, y: position in mm.
        pressure: normalised pressure 0–1; 0 means the pen is lifted.
        source: where it came from.
        tilt_x, tilt_y: tilt in degrees (−90–90), when known (None: not recorded).
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    pressure: np.ndarray
    source: str = "trajectory"
    tilt_x: np.ndarray | None = None
    tilt_y: np.ndarray | None = None

    @classmethod
    def checked(cls, t, x, y, pressure, source: object = "trajectory",
                lines: Sequence[int] | None = None, *, tilt_x=None, tilt_y=None) -> Trajectory:
        """Build a trajectory, raising :class:`RealPenError` naming ``source`` on bad data.

        The value ranges are the stroke sample's (:mod:`realpen.io.strokes`).

        Args:
            t: time in s; x, y: position in mm; pressure: normalised, 0–1.
            source: names the data in error messages.
            lines: the file line of each row (1-based), when the rows come from a file:
                errors then name the line; otherwise they name the row (1-based).
            tilt_x, tilt_y: tilt in degrees (−90–90), optional.
        """
        t, x, y, pressure = (np.asarray(a, dtype=np.float64).ravel() for a in (t, x, y, pressure))
        tilts = {name: None if value is None else np.asarray(value, dtype=np.float64).ravel()
                 for name, value in zip(TILT_FIELDS, (tilt_x, tilt_y))}
        columns = {"t": t, "x": x, "y": y, "pressure": pressure,
                   **{name: value for name, value in tilts.items() if value is not None}}
        if len({len(values) for values in columns.values()}) > 1:
            raise fail(source, f"{', '.join(columns)} differ in length")
        if lines is not None and len(lines) != len(t):
            raise ParameterError("lines", "one line number per row is needed")

        def where(row: int) -> str:
            return f"line {lines[row]}" if lines is not None else f"row {row + 1}"

        if len(t) < 2:
            raise fail(source, f"a trajectory needs at least 2 rows, has {len(t)}")
        for name, values in columns.items():
            bad = np.flatnonzero(~np.isfinite(values))
            if len(bad):
                raise fail(source, f"{where(bad[0])}: {name} is {values[bad[0]]:g} (NaN or "
                                   f"infinite)")
        steps = np.flatnonzero(np.diff(t) <= 0)
        if len(steps):
            row = steps[0] + 1
            raise fail(source, f"{where(row)}: t = {t[row]:g} s comes after {t[row - 1]:g} s "
                               f"({where(row - 1)}); t must increase strictly")
        low, high = PRESSURE_RANGE
        outside = np.flatnonzero((pressure < low) | (pressure > high))
        if len(outside):
            raise fail(source, f"{where(outside[0])}: pressure {pressure[outside[0]]:g} must be "
                               f"between {low:g} and {high:g}")
        ranges = [("x", POSITION_RANGE_MM, "mm"), ("y", POSITION_RANGE_MM, "mm")]
        ranges += [(name, TILT_RANGE_DEG, "degrees") for name in tilts if tilts[name] is not None]
        for name, (low, high), unit in ranges:
            values = columns[name]
            outside = np.flatnonzero((values < low) | (values > high))
            if len(outside):
                raise fail(source, f"{where(outside[0])}: {name} = {values[outside[0]]:g} {unit} "
                                   f"must be between {low:g} and {high:g}")
        if t[-1] - t[0] > MAX_DURATION_S:
            raise fail(source, f"lasts {t[-1] - t[0]:g} s, more than {MAX_DURATION_S:g} s "
                               f"(t must be in seconds)")
        return cls(t, x, y, pressure, str(source), tilts["tilt_x"], tilts["tilt_y"])

    @classmethod
    def from_samples(cls, samples: Iterable[StrokeSample],
                     source: object = "samples") -> Trajectory:
        """The trajectory of stroke samples (their ``t``, ``x``, ``y``, ``pressure`` and tilt;
        speed is measured again by :meth:`speed`).

        Args:
            samples: :class:`~realpen.io.strokes.StrokeSample` rows, ``t`` in s increasing.
            source: names them in error messages.
        """
        rows = np.array([sample.as_row() for sample in samples], dtype=np.float64)
        if rows.size == 0:
            raise fail(source, "a trajectory needs at least 2 rows, has 0")
        t, x, y, pressure, tilt_x, tilt_y, _ = rows.T
        return cls.checked(t, x, y, pressure, source, tilt_x=tilt_x, tilt_y=tilt_y)

    def to_samples(self, window_ms: float = SPEED_WINDOW_MS) -> list[StrokeSample]:
        """The rows as :class:`~realpen.io.strokes.StrokeSample` (speed in mm/s from
        :meth:`speed` over ``window_ms`` ms; tilt 0 degrees where not recorded)."""
        speed = self.speed(window_ms)
        zeros = np.zeros(len(self.t))
        tilt_x = self.tilt_x if self.tilt_x is not None else zeros
        tilt_y = self.tilt_y if self.tilt_y is not None else zeros
        return [StrokeSample(t=float(a), x=float(b), y=float(c), pressure=float(p),
                             tilt_x=float(tx), tilt_y=float(ty), speed=float(v))
                for a, b, c, p, tx, ty, v in zip(self.t, self.x, self.y, self.pressure,
                                                 tilt_x, tilt_y, speed)]

    @property
    def duration_s(self) -> float:
        """Time from the first to the last event, in s."""
        return float(self.t[-1] - self.t[0])

    def __len__(self) -> int:
        return len(self.t)

    def __repr__(self) -> str:
        down = float(np.mean(self.pressure > 0)) * 100 if len(self.t) else 0.0
        name = Path(self.source).name[:40]
        return (f"Trajectory({len(self.t)} events over {self.duration_s:.3g} s, pen down "
                f"{down:.0f} %, source={name!r})")

    def speed(self, window_ms: float = SPEED_WINDOW_MS) -> np.ndarray:
        """Causal pen speed at each event in mm/s, as the live page measures it.

        The path length since the newest earlier event at least ``window_ms`` ms back (the
        stroke's first event while the stroke is younger), over the time between the two. 0 at
        lifted rows (pressure 0) and at touch-downs (the first row, and a row with pressure > 0
        after a lifted one), where the page's meter restarts. See the module doc.

        Args:
            window_ms: the window in ms (default the page's 20 ms).
        """
        window = check_ms("window_ms", window_ms) / 1000.0
        speed = np.zeros(len(self.t))
        down = self.pressure > 0
        edges = np.flatnonzero(np.diff(np.concatenate([[0], down.astype(np.int8), [0]])))
        for first, stop in zip(edges[::2], edges[1::2]):  # each pen-down run is one stroke
            t = self.t[first:stop]
            steps = np.hypot(np.diff(self.x[first:stop]), np.diff(self.y[first:stop]))
            travelled = np.concatenate([[0.0], np.cumsum(steps)])
            # pen.js keeps the newest point whose successor is not older than t − window:
            # the newest earlier point with time ≤ t − window, else the stroke's first point.
            back = np.maximum(np.searchsorted(t, t - window, side="right") - 1, 0)
            span = t - t[back]
            moving = span > 0
            speed[first:stop][moving] = (travelled[moving] - travelled[back[moving]]) \
                / span[moving]
        return speed


def load_trajectory(path: str | os.PathLike) -> Trajectory:
    """Load a trajectory CSV with the header ``t,x,y,pressure`` (s, mm, mm, 0–1).

    Other columns are allowed (e.g. those of ``realpen strokes export``); ``tilt_x`` and
    ``tilt_y`` (degrees), when present, are read too.

    Raises:
        RealPenError: any problem with the file (see :meth:`Trajectory.checked`).
    """
    table = read_csv(path, TRAJECTORY_FIELDS, min_rows=2, optional=TILT_FIELDS)
    columns = table.columns
    return Trajectory.checked(columns["t"], columns["x"], columns["y"], columns["pressure"], path,
                              lines=table.lines, tilt_x=columns.get("tilt_x"),
                              tilt_y=columns.get("tilt_y"))
