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
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from realpen.errors import RealPenError, fail
from realpen.io.csvtable import is_number
from realpen.io.files import sha256_of

MODEL_DEFAULTS = {"lra": {"f0": 175.0, "q": 8.0}, "piezo": {"f0": 300.0, "q": 2.0}, "flat": {}}


@dataclass(frozen=True)
class Actuator:
    """A frequency response |H(f)|, from a model or a measurement.

    Attributes:
        spec: the spec string it came from (normalised, e.g. ``"lra:f0=175,q=8"``).
        kind: ``"lra"``, ``"piezo"``, ``"flat"`` or ``"measured"``.
        params: model parameters (f0 in Hz, dimensionless Q).
        table_hz, table_response: the measured response (linear magnitude), when measured.
    """

    spec: str
    kind: str
    params: dict = field(default_factory=dict)
    table_hz: np.ndarray | None = None
    table_response: np.ndarray | None = None

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
        """A JSON-ready description (the measured table included)."""
        data = {"spec": self.spec, "kind": self.kind, "params": self.params}
        if self.kind == "measured":
            data["params"] = {"sha256": sha256_of(self.spec)} if Path(self.spec).is_file() else {}
            data["table_hz"] = self.table_hz.tolist()
            data["table_response"] = self.table_response.tolist()
        return data


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


def parse_actuator(spec: str) -> Actuator:
    """Parse an actuator spec (see the module docs) or load a measured-response CSV.

    Raises:
        RealPenError: unknown model, bad parameter, or a malformed measured CSV.
    """
    spec = spec.strip()
    name, _, arguments = spec.partition(":")
    if name in MODEL_DEFAULTS:
        params = dict(MODEL_DEFAULTS[name])
        for item in filter(None, (part.strip() for part in arguments.split(","))):
            key, sep, value = item.partition("=")
            key = key.strip().lower()
            if not sep or key not in params:
                raise RealPenError(f"--actuator: '{item}' is not a parameter of {name} "
                                   f"(parameters: {', '.join(params) or 'none'})")
            try:
                params[key] = float(value)
            except ValueError:
                raise RealPenError(f"--actuator: {key}={value} is not a number") from None
            if not (np.isfinite(params[key]) and params[key] > 0):
                raise RealPenError(f"--actuator: {key} must be a positive finite number, got {value}")
        canonical = name + (":" + ",".join(f"{k}={v:g}" for k, v in params.items()) if params else "")
        return Actuator(canonical, name, params)
    path = Path(spec)
    if path.suffix.lower() == ".csv" or path.exists():
        return load_measured(path)
    raise RealPenError(f"--actuator: unknown actuator '{spec}' (use lra:f0=..,q=.., "
                       f"piezo:f0=..,q=.., flat, or a CSV of a measured response)")


def load_measured(path: str | Path) -> Actuator:
    """Load a measured response CSV: frequency (Hz, strictly increasing) and magnitude."""
    path = Path(path)
    if not path.exists():
        raise fail(path, "no such file")
    if path.is_dir():
        raise fail(path, "is a folder, not a CSV file")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise fail(path, "not a text CSV file") from None
    lines = [line for line in text.splitlines() if line.strip()]
    try:
        # Sniffed, not guessed: "50;0,1" is a decimal comma, not three columns.
        dialect = csv.Sniffer().sniff("\n".join(lines[:20]), delimiters=",;\t")
    except csv.Error:
        dialect = csv.excel
    rows = list(csv.reader(io.StringIO("\n".join(lines)), dialect))
    if dialect.delimiter != ",":
        rows = [[cell.replace(",", ".") for cell in row] for row in rows]
    if not rows:
        raise fail(path, "file is empty")
    in_db = False
    if not is_number(rows[0][0]):
        in_db = len(rows[0]) > 1 and re.search(r"db", rows[0][1], re.IGNORECASE) is not None
        rows = rows[1:]
    if len(rows) < 2:
        raise fail(path, "a measured response needs at least two rows of frequency, response")
    try:
        table = np.array([[float(row[0]), float(row[1])] for row in rows])
    except (ValueError, IndexError):
        raise fail(path, "every row needs two numbers: frequency in Hz, response") from None
    hz, response = table[:, 0], table[:, 1]
    if not np.all(np.isfinite(table)):
        raise fail(path, "contains NaN or infinite values")
    if np.any(hz <= 0):
        raise fail(path, "frequencies must be positive")
    if not np.all(np.diff(hz) > 0):
        raise fail(path, "frequencies are not strictly increasing")
    if in_db:
        response = 10 ** (response / 20)
    if np.any(response <= 0):
        raise fail(path, "response magnitudes must be positive (give dB in a column named dB)")
    return Actuator(str(path), "measured", {}, hz, response)



def weighting(actuator: Actuator, frequencies_hz: np.ndarray, band_hz: tuple[float, float],
              cap_db: float = 20.0) -> Weighting:
    """Equalising weights w(f) = min(H_ref / |H(f)|, 10^(cap_db/20)).

    Args:
        frequencies_hz: component frequencies in Hz (any shape; NaN allowed and passed through).
        band_hz: (low, high) band whose best response defines H_ref (weight 1).
        cap_db: largest boost in dB over the best-responding frequency.
    """
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
