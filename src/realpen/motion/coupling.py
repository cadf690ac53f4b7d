"""The coupling of a pen's motion to its feedback (Eq. 1 of the method), its smoother, and its fit.

``A_s = c_p·(P − c_op) + c_x·(v − c_ov)``, clamped to ``[0, a_max]``, and 0 whenever the pen is
lifted (``P <= 0``). ``P`` is the normalised pressure (0–1), ``v`` the pen speed in mm/s, and
``A_s`` a linear gain on the sound's loop unit, which is normalised to −20 dBFS RMS
(:data:`realpen.defaults.SOUND_REFERENCE_DBFS`),
so ``A_s = 1`` plays the recorded pen at that level.

The same JSON (``realpen.coupling/1``) drives the live app. What the app must reproduce,
per audio sample at rate ``fs`` (Hz):

    target = 0 if P <= 0 else min(max(c_p*(P - c_op) + c_x*(v - c_ov), 0), a_max)
    alpha  = 1 - exp(-1 / (fs * smoothing_ms / 1000))          # one-pole, time constant tau
    gain   = gain + alpha * (target - gain)                     # gain starts at 0
    rate   = min(max((v / rate_speed_ref) ** rate_exponent, rate_min), rate_max)  # same smoother

Web Audio's ``AudioParam.setTargetAtTime(target, t, tau)`` is this recursion exactly
(``v(t) = target + (v0 − target)·exp(−(t − t0)/tau)`` sampled every frame), so the app may use
it with ``tau = smoothing_ms / 1000``.

Defaults, chosen so ordinary handwriting (about 50 mm/s at half pressure) plays at gain 1, a
pen pressed but not moving is silent (``0.6·0.4 − 0.02·12 = 0``), and gain grows mostly with
speed, as the sliding noise of a real pen does: ``c_p = 0.6``, ``c_op = 0.1``,
``c_x = 0.02 per mm/s``, ``c_ov = 12 mm/s``, ``a_max = 2`` (+6 dB, reached near 100 mm/s),
5 ms smoothing. The playback rate rises as the fourth root of speed (about +19 % at twice the
reference speed), bounded to 0.8–1.25, so faster strokes sound brighter.

Fitting. Eq. 1 expands to ``c_p·P + c_x·v − (c_p·c_op + c_x·c_ov)``: measurements determine
``c_p``, ``c_x`` and the offset ``c_p·c_op + c_x·c_ov`` only, never ``c_op`` and ``c_ov``
apart. :func:`fit_coupling` fits those three by least squares on the clamped model and then
holds one threshold at a stated value (by default ``c_ov`` at the default 12 mm/s, the speed
below which sliding makes no sound) and solves the offset for the other. Any choice gives the
same gains; the fit reports which one was held.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from realpen.errors import ParameterError, fail
from realpen.io.csvtable import read_csv
from realpen.io.files import check_readable_file, write_json
from realpen.io.limits import load_json

__all__ = ["Coupling", "CouplingFit", "one_pole", "fit_coupling", "load_measurements", "FORMAT",
           "FIXABLE", "REPRODUCE_TOLERANCE", "MAX_SMOOTHING_MS"]

FORMAT = "realpen.coupling/1"
FIXABLE = ("c_ov", "c_op")
REPRODUCE_TOLERANCE = 1e-9  # gain units: the saved constants must give the fitted gains
MAX_SMOOTHING_MS = 10_000.0
"""The longest time constant of the smoother (ms): ten seconds, 2000 times the default 5 ms.
A stroke's render runs on for five time constants after its last event, so this bounds it."""


class Coupling(BaseModel):
    """Parameters of Eq. 1, its smoother and the speed-dependent playback rate.

    Attributes:
        c_p: gain per unit of normalised pressure.
        c_op: pressure offset (normalised, 0–1).
        c_x: gain per mm/s of speed.
        c_ov: speed offset in mm/s.
        a_max: upper clamp of the gain (linear).
        smoothing_ms: time constant of the one-pole smoother in ms (0: none; at most
            :data:`MAX_SMOOTHING_MS`).
        rate_speed_ref: speed in mm/s that plays at the recorded rate.
        rate_exponent: playback rate ∝ (v / rate_speed_ref) ** rate_exponent (0: constant rate).
        rate_min, rate_max: bounds of the playback rate.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    format: Literal["realpen.coupling/1"] = FORMAT
    c_p: float = 0.6
    c_op: float = 0.1
    c_x: float = 0.02
    c_ov: float = 12.0
    a_max: float = Field(2.0, gt=0)
    smoothing_ms: float = Field(5.0, ge=0, le=MAX_SMOOTHING_MS)
    rate_speed_ref: float = Field(50.0, gt=0)
    rate_exponent: float = Field(0.25, ge=0)
    rate_min: float = Field(0.8, gt=0, le=1)
    rate_max: float = Field(1.25, ge=1, le=4)

    @field_validator("*")
    @classmethod
    def _finite(cls, value):
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError("must be a finite number")
        return value

    def gain_raw(self, pressure: np.ndarray | float, speed: np.ndarray | float) -> np.ndarray:
        """Eq. 1 before smoothing: clamped to [0, a_max], 0 where ``pressure <= 0`` (lifted).

        Args:
            pressure: normalised pressure, 0–1.
            speed: pen speed in mm/s.
        """
        pressure = np.asarray(pressure, dtype=np.float64)
        speed = np.asarray(speed, dtype=np.float64)
        value = self.c_p * (pressure - self.c_op) + self.c_x * (speed - self.c_ov)
        return np.where(pressure > 0, np.clip(value, 0.0, self.a_max), 0.0)

    def playback_rate(self, speed: np.ndarray | float) -> np.ndarray:
        """Playback rate (1 = as recorded) for a speed in mm/s, before smoothing."""
        ratio = np.maximum(np.asarray(speed, dtype=np.float64), 0.0) / self.rate_speed_ref
        return np.clip(ratio ** self.rate_exponent, self.rate_min, self.rate_max)

    def smooth(self, values: np.ndarray, rate: float, initial: float = 0.0) -> np.ndarray:
        """Apply the one-pole smoother to a per-sample control signal at ``rate`` Hz.

        Args:
            values: the control signal, one value per sample.
            rate: samples per second, in Hz.
            initial: the state before the first sample.
        """
        return one_pole(values, rate, self.smoothing_ms, initial)

    def to_json(self) -> dict:
        """The JSON document (every field, ``format`` first)."""
        return self.model_dump()

    def __repr__(self) -> str:
        return (f"Coupling(c_p={self.c_p:.4g}, c_op={self.c_op:.4g}, c_x={self.c_x:.4g} per mm/s, "
                f"c_ov={self.c_ov:.4g} mm/s, a_max={self.a_max:.4g}, smoothing_ms="
                f"{self.smoothing_ms:.4g}, rate=(v/{self.rate_speed_ref:.4g})^"
                f"{self.rate_exponent:.4g} in [{self.rate_min:.4g}, {self.rate_max:.4g}])")

    __str__ = __repr__

    @classmethod
    def from_json(cls, data: object, source: object = "coupling") -> Coupling:
        """Validate a JSON document; problems become one :class:`RealPenError` line."""
        try:
            return cls.model_validate(data)
        except ValidationError as error:
            first = error.errors()[0]
            where = ".".join(str(part) for part in first["loc"]) or "document"
            raise fail(source, f"{where}: {first['msg']}") from None

    @classmethod
    def load(cls, path: str | os.PathLike) -> Coupling:
        """Load a coupling JSON file.

        Raises:
            RealPenError: one line naming the file: missing or empty; over a limit of
                :func:`realpen.io.limits.load_json` (size, nesting, number length) or not JSON;
                a field missing, unknown or out of range.
        """
        path = Path(path)
        check_readable_file(path)
        # The one bounded JSON reader: json.loads alone recurses without limit on nesting and
        # converts integers of any length.
        return cls.from_json(load_json(path), path)

    def save(self, path: str | os.PathLike) -> None:
        """Write the coupling JSON to ``path`` atomically."""
        write_json(path, self.to_json())


def one_pole(values: np.ndarray, rate: float, smoothing_ms: float,
             initial: float = 0.0) -> np.ndarray:
    """One-pole low-pass: ``y[n] = y[n-1] + alpha·(x[n] − y[n-1])``, ``y[-1] = initial``.

    ``alpha = 1 − exp(−1 / (rate · smoothing_ms / 1000))``; ``smoothing_ms = 0`` returns the
    input unchanged.

    Args:
        values: control signal, one value per sample.
        rate: samples per second, in Hz.
        smoothing_ms: time constant in ms.
        initial: the state before the first sample.
    """
    values = np.asarray(values, dtype=np.float64)
    if smoothing_ms <= 0 or len(values) == 0:
        return values.copy()
    # scipy.signal here, not at the top: the live server and the CLI load this module for the
    # Coupling type alone, and importing scipy.signal costs them seconds at every start.
    from scipy import signal

    alpha = 1.0 - math.exp(-1.0 / (rate * smoothing_ms / 1000.0))
    smoothed, _ = signal.lfilter([alpha], [1.0, alpha - 1.0], values,
                                 zi=[(1.0 - alpha) * initial])
    return smoothed


@dataclass(frozen=True)
class CouplingFit:
    """A fitted coupling and how well it fits.

    Attributes:
        coupling: the fitted parameters (other fields from the base coupling).
        offset: the identifiable constant ``c_p·c_op + c_x·c_ov`` (linear gain).
        fixed: which threshold was held (``"c_ov"`` or ``"c_op"``) and its value (mm/s for
            ``c_ov``, normalised pressure for ``c_op``).
        rows: pen-down measurements used; clamped: how many of them lie at 0 or ``a_max``.
        rmse: root-mean-square residual of the clamped model (amplitude units).
        r2: coefficient of determination of the clamped model.
    """

    coupling: Coupling
    offset: float
    fixed: tuple[str, float]
    rows: int
    clamped: int
    rmse: float
    r2: float

    def to_json(self) -> dict:
        """A report of the fit (the coupling itself is saved with :meth:`Coupling.save`)."""
        return {"coupling": self.coupling.to_json(), "offset": self.offset,
                "fixed": {"name": self.fixed[0], "value": self.fixed[1]}, "rows": self.rows,
                "clamped_rows": self.clamped, "rmse": self.rmse, "r2": self.r2}


def fit_coupling(pressure: np.ndarray, speed: np.ndarray, amplitude: np.ndarray,
                 fix: str = "c_ov", value: float | None = None,
                 base: Coupling | None = None, source: object = "measurements") -> CouplingFit:
    """Fit c_p, c_x and the offset of Eq. 1 by least squares; see the module doc.

    Rows with ``pressure <= 0`` (pen lifted) are ignored. The clamp is part of the model, so
    measurements at 0 or ``a_max`` only pull when the model predicts inside the range.

    Args:
        pressure: normalised pressure, 0–1.
        speed: speed in mm/s.
        amplitude: measured gain (same scale as ``A_s``).
        fix: the threshold held at ``value``: ``"c_ov"`` (default) or ``"c_op"``.
        value: its value, finite (mm/s for ``c_ov``, normalised pressure for ``c_op``; None:
            the base coupling's).
        base: supplies ``a_max``, the smoother, the playback rate and the default ``value``.
        source: names the data in error messages.

    Raises:
        ParameterError: ``fix`` not ``"c_ov"`` or ``"c_op"``, or a ``value`` that is not a finite
            number.
        RealPenError: too few pen-down rows, pressure and speed not varying independently, a
            held threshold that cannot be solved for (its partner's coefficient is 0), or
            constants that are not finite or too large to reproduce the fitted gains in floating
            point (a held value far from the data).
    """
    base = base or Coupling()
    if fix not in FIXABLE:
        raise ParameterError("fix", f"choose c_ov or c_op, got {fix!r}")
    held = float(getattr(base, fix) if value is None else value)
    if not math.isfinite(held):
        raise ParameterError("value", f"must be a finite number, got {held:g}")
    pressure, speed, amplitude = (np.asarray(a, dtype=np.float64) for a in
                                  (pressure, speed, amplitude))
    down = pressure > 0
    design = np.column_stack([pressure[down], speed[down], np.ones(int(down.sum()))])
    target = amplitude[down]
    if len(target) < 4:
        raise fail(source, f"needs at least 4 pen-down rows (pressure > 0) to fit, has "
                           f"{len(target)}")
    if np.linalg.matrix_rank(design) < 3:
        raise fail(source, "pressure and speed must both vary, and not in lockstep, to fit "
                           "c_p and c_x")
    inside = (target > 0) & (target < base.a_max)
    rows = inside if inside.sum() >= 3 and np.linalg.matrix_rank(design[inside]) == 3 else \
        np.ones_like(inside)
    start, *_ = np.linalg.lstsq(design[rows], target[rows], rcond=None)
    from scipy import optimize  # only fitting needs it (see one_pole for why not at the top)

    solution = optimize.least_squares(
        lambda theta: np.clip(design @ theta, 0.0, base.a_max) - target, start,
        x_scale="jac").x
    c_p, c_x, constant = (float(v) for v in solution)
    offset = -constant
    if fix == "c_ov":
        if abs(c_p) < 1e-12:
            raise fail(source, "pressure has no effect in these data; hold c_op instead")
        params = {"c_ov": held, "c_op": (offset - c_x * held) / c_p}
    else:
        if abs(c_x) < 1e-12:
            raise fail(source, "speed has no effect in these data; hold c_ov instead")
        params = {"c_op": held, "c_ov": (offset - c_p * held) / c_x}
    fitted = {"c_p": c_p, "c_x": c_x, **params}
    try:  # model_copy(update=...) would skip validation and let inf/NaN through
        coupling = Coupling.model_validate({**base.model_dump(), **fitted})
    except ValidationError as error:
        name = str(error.errors()[0]["loc"][0])
        raise fail(source, f"the fit gives {name} = {fitted.get(name, float('nan')):g}, not a "
                           f"finite number (the held {fix} = {held:g} is too far from the "
                           f"data)") from None
    predicted = coupling.gain_raw(pressure[down], speed[down])
    exact = np.clip(design @ solution, 0.0, base.a_max)
    if not np.allclose(predicted, exact, rtol=0.0, atol=REPRODUCE_TOLERANCE):
        other = "c_op" if fix == "c_ov" else "c_ov"
        raise fail(source, f"holding {fix} = {held:g} gives {other} = {params[other]:g}; "
                           f"constants this large no longer reproduce the fitted gains in "
                           f"floating point (hold a value nearer the data)")
    residual = predicted - target
    spread = float(np.sum((target - target.mean()) ** 2))
    return CouplingFit(coupling=coupling, offset=offset, fixed=(fix, held), rows=len(target),
                       clamped=int((~inside).sum()), rmse=float(np.sqrt(np.mean(residual ** 2))),
                       r2=float(1 - np.sum(residual ** 2) / spread) if spread > 0 else 0.0)


def load_measurements(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read a CSV with columns ``pressure`` (0–1), ``speed`` (mm/s) and ``amplitude`` (≥ 0).

    Raises:
        RealPenError: any problem with the file or a value out of range.
    """
    table = read_csv(path, ("pressure", "speed", "amplitude"))
    columns = table.columns
    checks = (("pressure", 0.0, 1.0), ("speed", 0.0, np.inf), ("amplitude", 0.0, np.inf))
    for name, low, high in checks:
        bad = np.flatnonzero((columns[name] < low) | (columns[name] > high))
        if len(bad):
            limits = f"between {low:g} and {high:g}" if np.isfinite(high) else f"at least {low:g}"
            raise fail(path, f"line {table.lines[bad[0]]}: {name} {columns[name][bad[0]]:g} "
                             f"must be {limits}")
    return columns["pressure"], columns["speed"], columns["amplitude"]
