"""Actuator frequency responses and the equalising weighting w(f) ∝ 1/|H(f)|.

An actuator is given by a spec string:

- ``lra:f0=175,q=8`` — a resonant actuator (linear resonant actuator, voice coil on a spring)
  modelled as a second-order band-pass, |H(f)| = 1 / √(1 + Q²(f/f0 − f0/f)²), peak 1 at f0.
- ``piezo:f0=300,q=2`` — a piezo bender driven in voltage: a second-order high-pass, the
  acceleration rising 40 dB/decade below its resonance f0 and flat above it,
  |H(f)| = r² / √((1 − r²)² + (r/Q)²) with r = f/f0.
- ``flat`` — an ideal actuator, |H| = 1 (no equalisation).
- a path to a CSV of a measured response: two columns, frequency in Hz (strictly increasing)
  and response magnitude (linear; or in dB when the column's header contains "db").

The weighting brings every component to the same output strength relative to its target. It is
normalised so that the best-responding frequency of the band gets weight 1, and capped (default
20 dB) so a component far from resonance does not take all of the actuator's drive.

This module imports numpy only (the CSV reader is loaded when a measured response is read), so
the profile schema can use :class:`Actuator` without loading scipy.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from realpen.checks import MAX_CAP_DB, require_number
from realpen.errors import ParameterError, fail

__all__ = ["Actuator", "Weighting", "MODEL_DEFAULTS", "KINDS", "parse_actuator", "as_actuator",
           "load_measured", "weighting"]

MODEL_DEFAULTS = {"lra": {"f0": 175.0, "q": 8.0}, "piezo": {"f0": 300.0, "q": 2.0}, "flat": {}}
KINDS = (*MODEL_DEFAULTS, "measured")


@dataclass(frozen=True, eq=False)
class Actuator:
    """A frequency response |H(f)|, from a model or a measurement.

    Build one with :func:`parse_actuator` (``"lra:f0=175,q=8"``) or :meth:`from_json`.

    Attributes:
        spec: the spec string it came from (normalised, e.g. ``"lra:f0=175,q=8"``; the CSV's
            path for a measured response).
        kind: ``"lra"``, ``"piezo"``, ``"flat"`` or ``"measured"``.
        params: model parameters (``f0`` in Hz, dimensionless ``q``); for a measured response,
            the CSV's ``sha256``.
        table_hz, table_response: the measured response (Hz, linear magnitude), when measured.
    """

    spec: str
    kind: str
    params: dict = field(default_factory=dict)
    table_hz: np.ndarray | None = None
    table_response: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ParameterError("actuator", f"unknown kind {self.kind!r} (choose from "
                                             f"{', '.join(KINDS)})")
        if self.kind == "measured":
            if self.table_hz is None or self.table_response is None:
                raise ParameterError("actuator", "a measured actuator needs table_hz and "
                                                 "table_response")
            hz = np.asarray(self.table_hz, dtype=np.float64)
            response = np.asarray(self.table_response, dtype=np.float64)
            if hz.ndim != 1 or hz.shape != response.shape or len(hz) < 2:
                raise ParameterError("actuator", "table_hz and table_response must be two "
                                                 "equally long lists of at least two values")
            if not (np.all(np.isfinite(hz)) and np.all(np.isfinite(response))
                    and np.all(hz > 0) and np.all(np.diff(hz) > 0) and np.all(response > 0)):
                raise ParameterError("actuator", "a measured table needs strictly increasing "
                                                 "positive frequencies and positive responses")
            object.__setattr__(self, "table_hz", hz)
            object.__setattr__(self, "table_response", response)
        else:
            for key in MODEL_DEFAULTS[self.kind]:
                if key not in self.params:
                    raise ParameterError("actuator", f"{self.kind} needs the parameter {key}")
                value = self.params[key]
                if isinstance(value, bool) or not isinstance(value, (int, float)) \
                        or not math.isfinite(value) or value <= 0:
                    raise ParameterError("actuator", f"{key} must be a positive finite number, "
                                                     f"got {value!r}")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Actuator):
            return NotImplemented
        same_tables = all(
            (a is None and b is None) or (a is not None and b is not None
                                          and np.array_equal(a, b))
            for a, b in ((self.table_hz, other.table_hz),
                         (self.table_response, other.table_response)))
        return (self.spec, self.kind, self.params) == (other.spec, other.kind, other.params) \
            and same_tables

    def __hash__(self) -> int:
        return hash((self.spec, self.kind))

    def __repr__(self) -> str:
        if self.kind == "measured":
            name = Path(self.spec).name
            name = name if len(name) <= 60 else name[:57] + "..."
            return (f"Actuator(measured {name!r}, {len(self.table_hz)} points, "
                    f"{self.table_hz[0]:g}–{self.table_hz[-1]:g} Hz)")
        return f"Actuator({self.spec!r})"

    def response(self, frequency_hz: np.ndarray | float) -> np.ndarray:
        """Magnitude |H(f)| (linear, dimensionless) at the given frequencies in Hz."""
        f = np.maximum(np.asarray(frequency_hz, dtype=np.float64), 1e-6)
        if self.kind == "flat":
            return np.ones_like(f)
        if self.kind == "lra":
            f0, q = self.params["f0"], self.params["q"]
            return 1.0 / np.sqrt(1.0 + q ** 2 * (f / f0 - f0 / f) ** 2)
        if self.kind == "piezo":
            r = f / self.params["f0"]
            return r ** 2 / np.sqrt((1 - r ** 2) ** 2 + (r / self.params["q"]) ** 2)
        # Measured: interpolate in log-frequency and log-magnitude, hold the end values.
        log_response = np.interp(np.log(f), np.log(self.table_hz), np.log(self.table_response))
        return np.exp(log_response)

    def to_json(self) -> dict:
        """A JSON-ready description that :meth:`from_json` reads back (the measured table
        included): ``spec``, ``kind``, ``params`` and, when measured, ``table_hz`` (Hz) and
        ``table_response`` (linear)."""
        data = {"spec": self.spec, "kind": self.kind, "params": dict(self.params)}
        if self.kind == "measured":
            data["table_hz"] = [float(v) for v in self.table_hz]
            data["table_response"] = [float(v) for v in self.table_response]
        return data

    @classmethod
    def from_json(cls, data: dict) -> Actuator:
        """The actuator of a :meth:`to_json` document (also the format-1 ``profile.json``
        section, whose model actuators carry ``table_hz: null``).

        Raises:
            ParameterError: (parameter ``actuator``) a malformed document.
        """
        if isinstance(data, Actuator):
            return data
        if not isinstance(data, dict):
            raise ParameterError("actuator", f"must be a JSON object, got {type(data).__name__}")
        known = {"spec", "kind", "params", "table_hz", "table_response"}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ParameterError("actuator", f"unknown field(s) {', '.join(unknown)}")
        spec, kind, params = data.get("spec"), data.get("kind"), data.get("params", {})
        if not isinstance(spec, str) or not isinstance(kind, str) or not isinstance(params, dict):
            raise ParameterError("actuator", "needs a string spec and kind and an object params")
        if kind == "measured":
            return cls(spec, kind, dict(params), np.asarray(data.get("table_hz") or []),
                       np.asarray(data.get("table_response") or []))
        if data.get("table_hz") is not None or data.get("table_response") is not None:
            raise ParameterError("actuator", f"a {kind} actuator has no measured table")
        return cls(spec, kind, {key: float(value) if isinstance(value, int)
                                and not isinstance(value, bool) else value
                                for key, value in params.items()})


@dataclass(frozen=True)
class Weighting:
    """Weights for a set of component frequencies.

    Attributes:
        weights: w(f) per component (dimensionless, ≥ 1 after normalisation).
        clipped: True where the cap limited the weight.
        cap_db: the cap in dB.
        reference: |H| that maps to weight 1 (the band's best response).
    """

    weights: np.ndarray
    clipped: np.ndarray
    cap_db: float
    reference: float


def as_actuator(actuator: Actuator | str) -> Actuator:
    """``actuator`` itself, or the actuator a spec string describes (see :func:`parse_actuator`)."""
    if isinstance(actuator, Actuator):
        return actuator
    if isinstance(actuator, (str, Path)):
        return parse_actuator(str(actuator))
    raise ParameterError("actuator", f"must be an Actuator or a spec string such as "
                                     f"'lra:f0=175,q=8', got {type(actuator).__name__}")


def parse_actuator(spec: str) -> Actuator:
    """Parse an actuator spec (see the module docs) or load a measured-response CSV.

    Example:
        >>> parse_actuator("lra:f0=175,q=8")
        Actuator('lra:f0=175,q=8')
        >>> float(parse_actuator("lra").response(175.0))
        1.0

    Raises:
        ParameterError: (parameter ``actuator``) an unknown model or a bad model parameter.
        RealPenError: a malformed measured CSV (naming the file).
    """
    spec = spec.strip()
    if not spec:  # as a path it would be the current folder
        raise ParameterError("actuator", "is empty (use lra:f0=..,q=.., piezo:f0=..,q=.., flat, "
                                         "or a CSV of a measured response)")
    name, _, arguments = spec.partition(":")
    if name in MODEL_DEFAULTS:
        params = dict(MODEL_DEFAULTS[name])
        for item in filter(None, (part.strip() for part in arguments.split(","))):
            key, sep, value = item.partition("=")
            key = key.strip().lower()
            if not sep or key not in params:
                raise ParameterError("actuator", f"'{item}' is not a parameter of {name} "
                                                 f"(parameters: {', '.join(params) or 'none'})")
            try:
                params[key] = float(value)
            except ValueError:
                raise ParameterError("actuator", f"{key}={value} is not a number") from None
            if not (np.isfinite(params[key]) and params[key] > 0):
                raise ParameterError("actuator", f"{key} must be a positive finite number, "
                                                 f"got {value}")
        canonical = name + (":" + ",".join(f"{k}={v:g}" for k, v in params.items()) if params else "")
        return Actuator(canonical, name, params)
    path = Path(spec)
    if path.suffix.lower() == ".csv" or path.exists():
        return load_measured(path)
    raise ParameterError("actuator", f"unknown actuator '{spec}' (use lra:f0=..,q=.., "
                                     f"piezo:f0=..,q=.., flat, or a CSV of a measured response)")


def load_measured(path: str | Path) -> Actuator:
    """Load a measured response CSV: frequency (Hz, strictly increasing) and magnitude.

    Raises:
        RealPenError: the file is missing, unreadable or malformed (naming the file).
    """
    from realpen.io.csvtable import read_csv
    from realpen.io.files import sha256_of

    path = Path(path)
    # The one CSV reader: the delimiter sniffed ("50;0,1" is a decimal comma, not three
    # columns), an optional header row, blank lines skipped, finite numbers, lines named.
    table = read_csv(path, (0, 1), header=None, min_rows=0,
                     row_hint="every row needs two numbers: frequency in Hz, response")
    header = table.header
    in_db = header is not None and len(header) > 1 and \
        re.search(r"db", header[1], re.IGNORECASE) is not None
    if len(table) < 2:
        raise fail(path, "a measured response needs at least two rows of frequency, response")
    hz, response = table.values[:, 0], table.values[:, 1]
    if np.any(hz <= 0):
        raise fail(path, "frequencies must be positive")
    if not np.all(np.diff(hz) > 0):
        raise fail(path, "frequencies are not strictly increasing")
    if in_db:
        with np.errstate(over="ignore"):
            response = 10 ** (response / 20)
        if not np.all(np.isfinite(response)):
            raise fail(path, "response levels in dB too high to be a magnitude")
    if np.any(response <= 0):
        raise fail(path, "response magnitudes must be positive (give dB in a column named dB)")
    return Actuator(str(path), "measured", {"sha256": sha256_of(path)}, hz, response)


def weighting(actuator: Actuator, frequencies_hz: np.ndarray, band_hz: tuple[float, float],
              cap_db: float = 20.0) -> Weighting:
    """Equalising weights w(f) = min(H_ref / |H(f)|, 10^(cap_db/20)).

    Args:
        actuator: the actuator (or its spec string).
        frequencies_hz: component frequencies in Hz (any shape; NaN allowed and passed through).
        band_hz: (low, high) band in Hz whose best response defines H_ref (weight 1).
        cap_db: largest boost in dB over the best-responding frequency.

    Raises:
        ParameterError: a ``cap_db`` that is negative, not finite or above
            :data:`~realpen.checks.MAX_CAP_DB`.
    """
    actuator = as_actuator(actuator)
    require_number("cap_db", cap_db, minimum=0.0, maximum=MAX_CAP_DB)
    low, high = max(band_hz[0], 1e-3), max(band_hz[1], band_hz[0] * 1.001)
    grid = np.geomspace(low, high, 2048)
    # The grid alone can miss the exact peak; add the points where a peak can be.
    extra = [actuator.params.get("f0", low)]
    if actuator.table_hz is not None:
        extra.extend(actuator.table_hz)
    grid = np.concatenate([grid, np.clip(extra, low, high)])
    reference = float(np.max(actuator.response(grid)))
    freqs = np.asarray(frequencies_hz, dtype=np.float64)
    response = actuator.response(np.nan_to_num(freqs, nan=1.0))
    raw = reference / response
    limit = 10 ** (cap_db / 20)
    clipped = (raw > limit) & np.isfinite(freqs)
    weights = np.where(np.isfinite(freqs), np.minimum(raw, limit), np.nan)
    return Weighting(weights, clipped, cap_db, reference)
