"""Penn Haptic Texture Toolkit (HaTT) texture models: load the XML files, synthesise vibration.

A HaTT file (``Models_<texture>.xml``; Culbertson, Lopez Delgado and Kuchenbecker, IEEE Haptics
Symposium 2014) holds one ARMA model of stylus acceleration per vertex of a Delaunay triangulation
of the (speed mm/s, force N) plane. The acceleration was recorded on three axes and reduced to one
by DFT321, in m/s² at ``SampleRate`` Hz (1000 Hz in the published files).

Conventions, as in the toolkit's renderer (``AccSynthHashMatrix.cpp``):

- excitation ``e[n]`` is Gaussian white noise of variance ``var`` (m/s²)²;
- ``y[n] = -Σ a_i y[n-i] + gain · (e[n] + Σ b_i e[n-i])``: ``gain`` scales the MA polynomial
  (``a = ARcoeff``, ``b = MAcoeff``, both starting with 1.0); AR-only files have no gain;
- ``<tri>`` lists 1-based model numbers (0-based here);
- between vertices, the line spectral frequencies (``ARlsf``, ``MAlsf``), ``var`` and ``gain``
  are blended with the barycentric weights of the triangle containing (speed, force), after
  clamping both into the modelled range. Blended LSFs stay ordered in (0, π), so the blended AR
  filter is always stable.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import signal

from realpen.checks import MAX_RATE_HZ, MIN_RATE_HZ, require_number
from realpen.errors import ParameterError, fail
from realpen.io.files import check_readable_file, sha256_of
from realpen.io.limits import MAX_FRAMES, MAX_MODEL_ORDER, MAX_NUMBER_CHARS, MAX_XML_BYTES, check_size
from realpen.io.recording import Recording

__all__ = ["ArmaModel", "HattModelSet", "load_hatt", "synthesize", "lsf_to_poly", "MAX_DURATION_S"]

MAX_DURATION_S = 86_400.0  # longest synthesis, in seconds (one day)


@dataclass(frozen=True, eq=False, repr=False)
class ArmaModel:
    """One ARMA texture model.

    Attributes:
        ar: AR (denominator) coefficients, ``ar[0] == 1``.
        ma: MA (numerator) coefficients before ``gain``, ``ma[0] == 1`` (``[1.0]`` for AR only).
        ar_lsf, ma_lsf: line spectral frequencies of ``ar`` and ``ma``, rad/sample in (0, π).
        variance: variance of the white-noise excitation, (m/s²)².
        gain: factor on the MA polynomial (dimensionless; 1 for AR-only models).
        speed: tangential speed, mm/s.
        force: normal force, N.
    """

    ar: np.ndarray
    ma: np.ndarray
    ar_lsf: np.ndarray
    ma_lsf: np.ndarray
    variance: float
    gain: float
    speed: float
    force: float

    def __repr__(self) -> str:
        return (f"ArmaModel(AR({len(self.ar) - 1}) MA({len(self.ma) - 1}) at {self.speed:g} mm/s, "
                f"{self.force:g} N, variance {self.variance:.3g}, gain {self.gain:.3g})")

    def output_variance(self) -> float:
        """Theoretical variance of the synthesised acceleration, (m/s²)²: ``var · Σ h[n]²``,
        with ``h`` the impulse response of ``gain · MA / AR``."""
        impulse = signal.unit_impulse(_decay_length(self.ar) + len(self.ma))
        h = signal.lfilter(self.gain * self.ma, self.ar, impulse)
        return self.variance * float(np.sum(h ** 2))


def lsf_to_poly(lsf: np.ndarray) -> np.ndarray:
    """Polynomial ``[1, a_1, ..., a_p]`` from its ``p`` line spectral frequencies (rad/sample).

    The LSFs alternate between the sum polynomial Q (first, third...) and the difference
    polynomial P; ``A = (P + Q) / 2``, with P also vanishing at z = 1 (and at z = -1 for odd
    ``p``) and Q at z = -1 for even ``p``.
    """
    lsf = np.asarray(lsf, dtype=np.float64)

    def product(freqs: np.ndarray) -> np.ndarray:
        poly = np.ones(1)
        for w in freqs:  # conjugate root pair e^{±jw} on the unit circle
            poly = np.convolve(poly, [1.0, -2.0 * math.cos(w), 1.0])
        return poly

    q, p = product(lsf[0::2]), product(lsf[1::2])
    if len(lsf) % 2 == 0:
        q, p = np.convolve(q, [1.0, 1.0]), np.convolve(p, [1.0, -1.0])
    else:
        p = np.convolve(p, [1.0, 0.0, -1.0])
    return ((p + q) / 2.0)[:len(lsf) + 1]


def _decay_length(ar: np.ndarray, tolerance: float = 1e-12) -> int:
    """Samples until the slowest pole of ``1 / AR`` decays below ``tolerance`` (16 .. 10⁶)."""
    radius = float(np.max(np.abs(np.roots(ar)), initial=0.0))
    steps = math.log(tolerance) / math.log(radius) if radius > 0 else 0.0
    return int(min(max(16, math.ceil(steps)), 1_000_000))


@dataclass(frozen=True, eq=False, repr=False)
class HattModelSet:
    """All models of one HaTT texture.

    Attributes:
        material: texture name (``"Book"``...).
        rate: sampling rate of the models, Hz.
        mu: kinetic friction coefficient (dimensionless).
        max_speed, max_force: largest modelled speed (mm/s) and force (N).
        vertices: shape (models, 2), (speed mm/s, force N) of each model.
        triangles: shape (T, 3), 0-based indices into ``models`` (Delaunay triangulation).
        models: one :class:`ArmaModel` per vertex.
        source, sha256: the file the set was read from, and the SHA-256 of its bytes.
    """

    material: str
    rate: float
    mu: float
    max_speed: float
    max_force: float
    vertices: np.ndarray
    triangles: np.ndarray
    models: tuple[ArmaModel, ...]
    source: str = "memory"
    sha256: str | None = None

    def __repr__(self) -> str:
        return (f"HattModelSet({self.material!r}, {len(self.models)} models at {self.rate:g} Hz, "
                f"speed to {self.max_speed:g} mm/s, force to {self.max_force:g} N, "
                f"from {Path(self.source).name})")

    def model_at(self, speed_mm_s: float, force_n: float) -> ArmaModel:
        """The model at (speed mm/s, force N), clamped into range and blended as the toolkit does.

        A point that no triangle contains gets the nearest vertex's model; at a vertex, that
        vertex's model is returned unchanged (its stored coefficients).

        Raises:
            ParameterError: ``speed_mm_s`` or ``force_n`` is not a finite number.
        """
        require_number("speed_mm_s", speed_mm_s)
        require_number("force_n", force_n)
        low, high = self.vertices.min(axis=0), self.vertices.max(axis=0)
        point = np.clip([speed_mm_s, force_n], low, high)
        corners = self.vertices[self.triangles]  # (T, 3, 2); solve p = c + w0 (a - c) + w1 (b - c)
        w01 = np.linalg.solve(corners[:, :2].transpose(0, 2, 1) - corners[:, 2:].transpose(0, 2, 1),
                              (point - corners[:, 2])[..., None])[..., 0]
        weights = np.concatenate([w01, 1.0 - w01.sum(axis=1, keepdims=True)], axis=1)
        best = int(np.argmax(weights.min(axis=1)))
        if weights[best].min() < -1e-9:  # outside the triangulation: nearest vertex (scaled axes)
            distance = np.sum(((self.vertices - point) / np.maximum(high - low, 1e-12)) ** 2, axis=1)
            return self.models[int(np.argmin(distance))]
        w = np.clip(weights[best], 0.0, None) / np.clip(weights[best], 0.0, None).sum()
        if w.max() > 1.0 - 1e-12:
            return self.models[int(self.triangles[best, np.argmax(w)])]
        corner_models = [self.models[i] for i in self.triangles[best]]

        def blend(attr: str):
            return sum(wk * getattr(m, attr) for wk, m in zip(w, corner_models))

        ar_lsf, ma_lsf = blend("ar_lsf"), blend("ma_lsf")
        return ArmaModel(ar=lsf_to_poly(ar_lsf), ma=lsf_to_poly(ma_lsf), ar_lsf=ar_lsf,
                         ma_lsf=ma_lsf, variance=float(blend("variance")),
                         gain=float(blend("gain")), speed=float(point[0]), force=float(point[1]))


def _values(path: Path, node: ET.Element, tag: str, where: str = "", single: bool = False):
    """The numbers of ``<tag>`` (its text, or its ``<value>`` children): a float or an array."""
    child = node.find(tag)
    if child is None:
        raise fail(path, f"missing <{tag}>{where}")
    texts = [child.text or ""] if single else [v.text or "" for v in child.findall("value")]
    _check_number_lengths(path, texts, f"<{tag}>{where}")
    try:
        values = np.array([float(t.strip()) for t in texts], dtype=np.float64)
    except ValueError as error:
        raise fail(path, f"<{tag}>{where} is not numeric ({error})") from None
    if values.size == 0 or not np.all(np.isfinite(values)):
        raise fail(path, f"<{tag}>{where} holds no values or non-finite ones")
    return float(values[0]) if single else values


def _check_number_lengths(path: Path, texts: list[str], what: str) -> None:
    """Refuse a number written with more than ``MAX_NUMBER_CHARS`` characters: int() of
    thousands of digits is refused by Python itself (and slow before that)."""
    longest = max((len(text.strip()) for text in texts), default=0)
    if longest > MAX_NUMBER_CHARS:
        raise fail(path, f"{what} holds a number of {longest:,} characters; numbers are limited "
                         f"to {MAX_NUMBER_CHARS}")


def _load_model(path: Path, node: ET.Element, where: str) -> ArmaModel:
    def number(tag: str) -> float:
        return _values(path, node, tag, where, single=True)

    has_ma = node.find("MAcoeff") is not None
    ar, ar_lsf = _values(path, node, "ARcoeff", where), _values(path, node, "ARlsf", where)
    ma = _values(path, node, "MAcoeff", where) if has_ma else np.ones(1)
    ma_lsf = _values(path, node, "MAlsf", where) if has_ma else np.zeros(0)
    for name, poly, lsf in (("AR", ar, ar_lsf), ("MA", ma, ma_lsf)):
        if len(poly) - 1 > MAX_MODEL_ORDER:  # before any root finding, which costs order³
            raise fail(path, f"{name} order{where} is {len(poly) - 1}; models are limited to "
                             f"order {MAX_MODEL_ORDER}")
        if poly[0] != 1.0 or len(lsf) != len(poly) - 1:
            raise fail(path, f"{name} coefficients{where} must start with 1.0 and have one more "
                             f"value than the {len(lsf)} {name} LSFs")
        if len(lsf) and not (lsf[0] > 0 and lsf[-1] < math.pi and np.all(np.diff(lsf) > 0)):
            raise fail(path, f"{name} LSFs{where} are not increasing within (0, π)")
    if number("var") < 0:
        raise fail(path, f"<var>{where} is negative ({number('var')})")
    return ArmaModel(ar=ar, ma=ma, ar_lsf=ar_lsf, ma_lsf=ma_lsf, variance=number("var"),
                     gain=number("gain") if has_ma else 1.0, speed=number("speedMod"),
                     force=number("forceMod"))


def load_hatt(path: str | os.PathLike) -> HattModelSet:
    """Read a HaTT ``Models_<texture>.xml`` file.

    Raises:
        RealPenError: missing, empty or non-XML files, missing fields, non-numeric values,
            inconsistent counts (models, speeds, forces, triangles, orders), triangle indices
            outside 1..numMod, degenerate triangles, disordered LSFs; a file over
            ``MAX_XML_BYTES``, a ``<SampleRate>`` outside ``MIN_RATE_HZ``..``MAX_RATE_HZ``, an
            order over ``MAX_MODEL_ORDER``, a number over ``MAX_NUMBER_CHARS`` characters
            (limits of :mod:`realpen.io.limits`).
    """
    path = Path(path)
    check_readable_file(path)
    check_size(path, MAX_XML_BYTES, "XML model files")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as error:
        raise fail(path, f"not a valid XML file ({error})") from None
    if root.tag != "modelSet":
        raise fail(path, f"not a HaTT model file (root element <{root.tag}>, expected <modelSet>)")
    def number(tag: str) -> float:
        return _values(path, root, tag, single=True)

    rate, count = number("SampleRate"), number("numMod")
    if rate <= 0 or count < 3 or count != int(count):
        raise fail(path, "needs a positive <SampleRate> and an integer <numMod> ≥ 3")
    if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
        raise fail(path, f"<SampleRate> {rate:g} Hz is outside the {MIN_RATE_HZ:,}–"
                         f"{MAX_RATE_HZ:,} Hz RealPen reads")
    speeds, forces = _values(path, root, "speedList"), _values(path, root, "forceList")
    nodes = root.findall("model")
    if not len(speeds) == len(forces) == len(nodes) == int(count):
        raise fail(path, f"<numMod> is {int(count)} but the file has {len(speeds)} speeds, "
                         f"{len(forces)} forces and {len(nodes)} models")
    models = tuple(_load_model(path, node, f" of model {k + 1}") for k, node in enumerate(nodes))
    vertices = np.stack([speeds, forces], axis=1)
    for k, model in enumerate(models):
        if not np.allclose([model.speed, model.force], vertices[k], rtol=1e-6, atol=1e-6):
            raise fail(path, f"model {k + 1} is at ({model.speed:g} mm/s, {model.force:g} N), "
                             f"not at vertex {k + 1} of the speed/force lists")
        if len(model.ar) != len(models[0].ar) or len(model.ma) != len(models[0].ma):
            raise fail(path, f"model {k + 1} has a different AR/MA order from model 1")
    tris = [[(v.text or "").strip() for v in t.findall("value")] for t in root.findall("tri")]
    if not tris or any(len(t) != 3 for t in tris):
        raise fail(path, "needs <tri> elements of exactly 3 vertex indices each")
    _check_number_lengths(path, [v for t in tris for v in t], "<tri>")
    try:
        triangles = np.array([[int(v) for v in t] for t in tris], dtype=np.int64)
    except ValueError as error:
        raise fail(path, f"<tri> has a non-integer vertex index ({error})") from None
    except OverflowError:
        raise fail(path, "<tri> has a vertex index beyond any model's count") from None
    if root.find("numTri") is not None and number("numTri") != len(triangles):
        raise fail(path, f"<numTri> does not match the {len(triangles)} <tri> elements")
    if triangles.min() < 1 or triangles.max() > count:
        raise fail(path, f"<tri> vertex indices must be 1..{int(count)} "
                         f"(got {triangles.min()}..{triangles.max()})")
    triangles -= 1
    corners = vertices[triangles] / np.maximum(np.ptp(vertices, axis=0), 1e-12)  # unit box
    if np.any(np.abs(np.linalg.det(corners[:, :2] - corners[:, 2:])) < 1e-12):
        raise fail(path, "a <tri> triangle is degenerate (its vertices are collinear)")
    return HattModelSet(material=(root.findtext("material") or "").strip() or path.stem,
                        rate=rate, mu=number("mu"), max_speed=number("maxSpeed"),
                        max_force=number("maxForce"), vertices=vertices, triangles=triangles,
                        models=models, source=str(path), sha256=sha256_of(path))


def synthesize(model_set: HattModelSet, speed_mm_s: float | np.ndarray, force_n: float | np.ndarray,
               duration_s: float, seed: int = 0, update_s: float = 0.01) -> Recording:
    """Synthesise stylus acceleration (m/s²) from a HaTT model set, e.g.
    ``synthesize(load_hatt("Models_Book.xml"), 150.0, 1.5, 2.0)``.

    Args:
        speed_mm_s, force_n: tangential speed (mm/s) and normal force (N): numbers, or arrays of
            one value per output sample; then the model is re-interpolated every ``update_s``
            seconds (block means) and the filter memory carries over (direct form I, as in the
            toolkit).
        duration_s: output length in seconds (rounded to whole samples at ``model_set.rate``).
        seed: seed of the white-noise excitation (an integer ≥ 0); equal seeds give equal
            outputs.
        update_s: how often, in seconds, a time-varying speed or force re-interpolates the model.

    Returns:
        A one-axis :class:`Recording` (axis ``"dft321"``, units ``"m/s^2"``) at the set's rate,
        stationary from its first sample (a filter warm-up is discarded).

    Raises:
        ParameterError: a ``duration_s`` shorter than one sample, longer than
            :data:`MAX_DURATION_S` or of more than ``MAX_FRAMES`` samples at the set's rate
            (:mod:`realpen.io.limits`), a negative or non-integer
            ``seed``, a non-positive ``update_s``, or a speed or force that is not finite or
            not one number per output sample.
    """
    # One day at 1 kHz is 86.4 M samples (0.7 GB as float64): longer is a typo, not a recording.
    require_number("duration_s", duration_s, minimum=0.0, maximum=MAX_DURATION_S, inclusive=False)
    frames = int(round(duration_s * model_set.rate))
    if frames < 1:
        raise ParameterError("duration_s", f"must give at least one sample at "
                                           f"{model_set.rate:g} Hz, got {duration_s:g} s")
    if frames > MAX_FRAMES:
        raise ParameterError("duration_s", f"gives {frames:,} samples at {model_set.rate:g} Hz; "
                                           f"recordings are limited to {MAX_FRAMES:,}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ParameterError("seed", f"must be a whole number >= 0, got {seed!r}")
    require_number("update_s", update_s, minimum=0.0, inclusive=False)
    tracks = []
    for name, value in (("speed_mm_s", speed_mm_s), ("force_n", force_n)):
        value = np.asarray(value, dtype=np.float64)
        if value.ndim > 1 or (value.ndim == 1 and len(value) != frames):
            raise ParameterError(name, f"needs one number or {frames} values, got shape "
                                       f"{value.shape}")
        if not np.all(np.isfinite(value)):
            raise ParameterError(name, "must be finite")
        tracks.append(np.broadcast_to(value, (frames,)))
    speeds, forces = tracks
    constant = np.ptp(speeds) == 0 and np.ptp(forces) == 0
    block = frames if constant else max(1, int(round(update_s * model_set.rate)))
    starts = range(0, frames, block)
    models = [model_set.model_at(float(speeds[s:s + block].mean()),
                                 float(forces[s:s + block].mean())) for s in starts]
    warm = _decay_length(models[0].ar)
    noise = np.random.default_rng(seed).standard_normal(warm + frames)
    segments = [(models[0], noise[:warm])] + [(m, noise[warm + s:warm + s + block])
                                                for m, s in zip(models, starts)]
    out, past_y, past_e = [], np.zeros(0), np.zeros(0)
    for model, white in segments:
        excitation = white * math.sqrt(model.variance)
        numerator = model.gain * model.ma
        state = signal.lfiltic(numerator, model.ar, past_y[::-1], past_e[::-1])
        out.append(signal.lfilter(numerator, model.ar, excitation, zi=state)[0])
        past_y = np.concatenate([past_y, out[-1]])[-len(model.ar):]
        past_e = np.concatenate([past_e, excitation])[-len(model.ma):]

    def span(v: np.ndarray, unit: str) -> str:
        return f"{v[0]:g} {unit}" if np.ptp(v) == 0 else f"{v.min():g}–{v.max():g} {unit}"

    source = (f"HaTT '{model_set.material}' at {span(speeds, 'mm/s')}, {span(forces, 'N')} "
              f"({Path(model_set.source).name})")
    return Recording(np.concatenate(out[1:]), model_set.rate, ("dft321",), units="m/s^2",
                     source=source, sha256=model_set.sha256,
                     history=(f"hatt:synthesize:seed={seed}",))
