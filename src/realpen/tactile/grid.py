"""A feel that follows the pen: tactile patterns at several (speed, force) points.

A :class:`VibrationGrid` holds one :class:`~realpen.tactile.pattern.TactilePattern` per
(speed mm/s, force N) point — from recordings made at those points, or from every vertex of a
HaTT texture model. At run time the pen's speed and force pick a mix of the points, as HaTT's
own renderer does (Culbertson, Lopez Delgado and Kuchenbecker 2014): barycentric weights over a
Delaunay triangulation of the points, with both axes divided by their range (:attr:`scale`) so
that mm/s and N weigh alike.

- one point: that point (a single-point grid is the profile's one pattern, as before);
- points on one line (no triangle can be made): linear interpolation along the line, clamped
  to its ends;
- outside the triangulation's hull: the nearest point of the hull (scaled axes), then as inside;
- at a grid point exactly: that point alone, weight 1.

The weights are continuous in (speed, force) and sum to 1. Mixing rule: every point's loop
plays, all in sync (same start, same length), point i's with gain ``sqrt(w_i)``: an
equal-power crossfade of uncorrelated patterns (:meth:`VibrationGrid.gains`). So that the loops
can play in sync, every pattern of a grid has the same rate, number of sub-patterns and
sub-pattern length.

The JSON form (``profile.json``'s ``grid`` section, and what the live page is sent)::

    {"full_pressure_force_n": 4.0, "reference": k,
     "points": [{"speed_mm_s": .., "force_n": .., "tactile": TactilePattern.to_json()}, ..]}

``full_pressure_force_n`` is the force in N at page pressure 1 (pressure 0–1 maps linearly);
``reference`` is the index of the point whose pattern is the profile's own ``tactile`` section.

numpy only at import (scipy.spatial is imported when a grid of three or more points that are
not on one line is first asked for weights): the profile schema imports this module.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from realpen.checks import (
    MAX_FORCE_N,
    MAX_GRID_POINTS,
    MAX_PATTERN_FRAMES,
    MAX_SPEED_MM_S,
    check_magnitude,
    is_number,
)
from realpen.errors import ParameterError, RealPenError, fail
from realpen.tactile.pattern import TactilePattern, content_version

if TYPE_CHECKING:
    from realpen.datasets.hatt import HattModelSet
    from realpen.io.recording import Recording
    from realpen.tactile.actuator import Actuator
    from realpen.tactile.conditions import TactileParams

__all__ = ["GridPoint", "VibrationGrid", "grid_from_recordings", "grid_from_hatt",
           "central_point", "FULL_PRESSURE_FORCE_N", "HATT_SECONDS"]

FULL_PRESSURE_FORCE_N = 4.0
"""Default force in N at page pressure 1: a firm press with a pen (HaTT records 0–8 N)."""
_SAME = 1e-12  # scaled distance under which a query is at a grid point
_APART = 1e-9  # scaled distance two grid points must keep (else they cannot be told apart)
_LINE = 1e-9  # smaller-to-larger singular value ratio of the scaled points: on one line
_TINY = 1e-12  # weights below this are rounding (clipped to 0, the rest renormalised)




@dataclass(frozen=True, repr=False)
class GridPoint:
    """One point of a :class:`VibrationGrid`: the pattern felt at a speed and a force.

    Attributes:
        speed_mm_s: pen speed in mm/s (≥ 0).
        force_n: normal force in N (≥ 0).
        pattern: the :class:`~realpen.tactile.pattern.TactilePattern` at that speed and force.
    """

    speed_mm_s: float
    force_n: float
    pattern: TactilePattern

    def __post_init__(self) -> None:
        object.__setattr__(self, "speed_mm_s", check_magnitude("speed_mm_s", self.speed_mm_s,
                                                       MAX_SPEED_MM_S))
        object.__setattr__(self, "force_n", check_magnitude("force_n", self.force_n, MAX_FORCE_N))
        if not isinstance(self.pattern, TactilePattern):
            raise ParameterError("pattern", f"must be a TactilePattern, got "
                                            f"{type(self.pattern).__name__}")

    def __repr__(self) -> str:
        return f"GridPoint({self.speed_mm_s:g} mm/s, {self.force_n:g} N, {self.pattern!r})"

    def to_json(self) -> dict:
        """``{"speed_mm_s", "force_n", "tactile": TactilePattern.to_json()}``."""
        return {"speed_mm_s": self.speed_mm_s, "force_n": self.force_n,
                "tactile": self.pattern.to_json()}


@dataclass(frozen=True, repr=False)
class _Geometry:
    """What the weights need, computed once per grid."""

    kind: str  # "single", "line" or "plane"
    scaled: np.ndarray  # (P, 2) points divided by the scale
    triangles: np.ndarray  # (T, 3) int64
    delaunay: Any = None  # scipy.spatial.Delaunay ("plane")
    hull: np.ndarray | None = None  # (H, 2) hull edges ("plane")
    origin: np.ndarray | None = None  # ("line") a point of the line
    direction: np.ndarray | None = None  # ("line") its unit direction
    order: np.ndarray | None = None  # ("line") points in order along it
    along: np.ndarray | None = None  # ("line") their positions along it, ascending


@dataclass(frozen=True, repr=False)
class VibrationGrid:
    """Tactile patterns at (speed, force) points, and the mix of them at any speed and force.

    Attributes:
        points: the :class:`GridPoint` s (1 to :data:`MAX_GRID_POINTS`, at distinct
            (speed, force)); their patterns share rate, sub-pattern count and length.
        full_pressure_force_n: force in N at page pressure 1 (pressure 0–1 maps linearly).
        reference: index of the point whose pattern is the profile's ``tactile`` section.
        notes: things the user should know about how it was made (not part of the grid).
        provenance: where it came from (``sources``: files; ``model``: a HaTT model), not part
            of the grid.

    Example:
        >>> from realpen.tactile.pattern import Component
        >>> slow = TactilePattern([[Component(100.0, 0.5)]])
        >>> fast = TactilePattern([[Component(250.0, 0.5)]])
        >>> grid = VibrationGrid([GridPoint(20, 2, slow), GridPoint(100, 2, fast)])
        >>> grid.weights(60, 2)
        (array([0, 1]), array([0.5, 0.5]))
        >>> grid.gains(60, 2).round(4).tolist()
        [0.7071, 0.7071]
    """

    points: tuple[GridPoint, ...]
    full_pressure_force_n: float = FULL_PRESSURE_FORCE_N
    reference: int = 0
    notes: tuple[str, ...] = field(default=(), compare=False)
    provenance: dict = field(default_factory=dict, compare=False)
    _geometry: _Geometry | None = field(default=None, init=False, compare=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if isinstance(self.points, (str, bytes, dict, GridPoint)):
            raise ParameterError("points", "must be a sequence of GridPoint")
        points = tuple(self.points)
        if not points:
            raise ParameterError("points", "a grid needs at least one point")
        if len(points) > MAX_GRID_POINTS:
            raise ParameterError("points", f"{len(points):,} points; a grid holds at most "
                                           f"{MAX_GRID_POINTS}")
        for index, point in enumerate(points):
            if not isinstance(point, GridPoint):
                raise ParameterError("points", f"point {index} must be a GridPoint, got "
                                               f"{type(point).__name__}")
        first = points[0].pattern
        for index, point in enumerate(points[1:], start=1):
            pattern = point.pattern
            if (pattern.rate, len(pattern.subpatterns), pattern.subpattern_ms) != \
                    (first.rate, len(first.subpatterns), first.subpattern_ms):
                raise ParameterError("points", f"the pattern of point {index} is "
                                               f"{_shape(pattern)}, that of point 0 "
                                               f"{_shape(first)}; a grid's loops play in sync, "
                                               f"so they must agree")
        if len(points) * first.frames > MAX_PATTERN_FRAMES:
            raise ParameterError("points", f"{len(points)} loops of {first.frames:,} samples "
                                           f"are more than {MAX_PATTERN_FRAMES:,} in all")
        seen: dict[tuple[float, float], int] = {}
        for index, point in enumerate(points):
            key = (point.speed_mm_s, point.force_n)
            if key in seen:
                raise ParameterError("points", f"points {seen[key]} and {index} are both at "
                                               f"{key[0]:g} mm/s, {key[1]:g} N")
            seen[key] = index
        # A single point plays its pattern's own samples (a profile's tactile.wav); several
        # are mixed from their JSON, which must then be a playable level.
        for index, point in enumerate(points if len(points) > 1 else ()):
            power = _largest_power(point.pattern)
            if power > 1.0:
                raise ParameterError("points", f"the pattern of point {index} carries a "
                                               f"mean-square power of {power:.3g} in a "
                                               f"sub-pattern; a grid's patterns are at most full "
                                               f"scale (1)")
        set_(self, "points", points)
        value = check_magnitude("full_pressure_force_n", self.full_pressure_force_n, MAX_FORCE_N)
        if value <= 0:
            raise ParameterError("full_pressure_force_n", "must be > 0, got 0")
        set_(self, "full_pressure_force_n", value)
        if isinstance(self.reference, (bool, np.bool_)) or \
                not isinstance(self.reference, (int, np.integer)) or \
                not 0 <= self.reference < len(points):
            raise ParameterError("reference", f"must be a point's index, 0 to {len(points) - 1}, "
                                              f"got {self.reference!r}")
        set_(self, "reference", int(self.reference))
        set_(self, "notes", tuple(self.notes))
        set_(self, "provenance", dict(self.provenance or {}))
        scaled = self.coordinates / self.scale
        if len(points) > 1:
            gaps = np.sqrt(np.sum((scaled[:, None] - scaled[None]) ** 2, axis=2))
            gaps[np.diag_indices(len(points))] = np.inf
            first_pair = np.unravel_index(np.argmin(gaps), gaps.shape)
            if gaps[first_pair] < _APART:
                a, b = sorted(int(i) for i in first_pair)
                raise ParameterError("points", f"points {a} and {b} are too close to tell apart")

    @classmethod
    def single(cls, pattern: TactilePattern, speed_mm_s: float = 0.0, force_n: float = 0.0,
               full_pressure_force_n: float = FULL_PRESSURE_FORCE_N) -> VibrationGrid:
        """A grid of one point: ``pattern`` at any speed and force (what a profile without a
        grid plays)."""
        return cls((GridPoint(speed_mm_s, force_n, pattern),), full_pressure_force_n, 0)

    # --- what it is -----------------------------------------------------------------------

    @property
    def patterns(self) -> tuple[TactilePattern, ...]:
        """Each point's pattern, in point order."""
        return tuple(point.pattern for point in self.points)

    @property
    def reference_pattern(self) -> TactilePattern:
        """The reference point's pattern (the profile's ``tactile`` section)."""
        return self.points[self.reference].pattern

    @property
    def rate(self) -> int:
        """The patterns' rate in Hz."""
        return self.points[0].pattern.rate

    @property
    def coordinates(self) -> np.ndarray:
        """(P, 2) float64: each point's (speed mm/s, force N)."""
        return np.array([[p.speed_mm_s, p.force_n] for p in self.points], dtype=np.float64)

    @property
    def scale(self) -> tuple[float, float]:
        """(mm/s, N): each axis is divided by it before anything is measured — its range over
        the points, or 1 where every point has the same value."""
        span = np.ptp(self.coordinates, axis=0)
        return tuple(float(s) if s > 0 else 1.0 for s in span)

    @property
    def triangles(self) -> np.ndarray:
        """(T, 3) int64: the Delaunay triangles (point indices) over the scaled points; empty
        (0, 3) for one point or points on one line."""
        return self._geo().triangles.copy()

    @property
    def version(self) -> str:
        """12 hex digits of the SHA-256 of the canonical form of :meth:`to_json`."""
        return content_version(self.to_json())

    def __len__(self) -> int:
        return len(self.points)

    def __repr__(self) -> str:
        low, high = self.coordinates.min(axis=0), self.coordinates.max(axis=0)
        count = len(self.points)
        return (f"VibrationGrid({count} point{'s' if count != 1 else ''}, speed "
                f"{low[0]:g}–{high[0]:g} mm/s, force {low[1]:g}–{high[1]:g} N, reference "
                f"{self.reference})")

    # --- the mix --------------------------------------------------------------------------

    def weights(self, speed_mm_s: float, force_n: float) -> tuple[np.ndarray, np.ndarray]:
        """The points that mix at (speed mm/s, force N) and their weights.

        Returns:
            (indices, weights): int64 point indices, ascending, and float64 weights > 0 that
            sum to 1 (one to three points; at a grid point exactly, that point with weight 1).

        Raises:
            ParameterError: ``speed_mm_s`` or ``force_n`` is not a finite number.
        """
        row = self.weight_matrix(np.array([speed_mm_s]), np.array([force_n]))[0]
        indices = np.flatnonzero(row)
        return indices.astype(np.int64), row[indices]

    def gains(self, speed_mm_s: float, force_n: float) -> np.ndarray:
        """Each point's loop gain at (speed mm/s, force N): ``sqrt(w_i)`` (equal power),
        float64 of shape (P,), 0 for the points that do not mix."""
        return np.sqrt(self.weight_matrix(np.array([speed_mm_s]), np.array([force_n]))[0])

    def weight_matrix(self, speeds_mm_s: np.ndarray, forces_n: np.ndarray) -> np.ndarray:
        """The weights of every point at many (speed mm/s, force N): (N, P) float64, each
        row ≥ 0 and summing to 1 (see :meth:`weights`).

        Raises:
            ParameterError: the speeds or forces are not finite numbers of one shape.
        """
        speeds = _finite_array("speed_mm_s", speeds_mm_s)
        forces = _finite_array("force_n", forces_n)
        if speeds.shape != forces.shape:
            raise ParameterError("force_n", f"needs one force per speed: {forces.size} forces "
                                            f"for {speeds.size} speeds")
        geo = self._geo()
        count = len(self.points)
        out = np.zeros((speeds.size, count))
        if count == 1:
            out[:, 0] = 1.0
            return out
        query = np.stack([speeds, forces], axis=1) / np.array(self.scale)
        if geo.kind == "line":
            _along_line(geo, query, out)
        else:
            _in_plane(geo, query, out)
        out[out < _TINY] = 0.0
        out /= out.sum(axis=1, keepdims=True)
        distance = np.sum((query[:, None, :] - geo.scaled[None]) ** 2, axis=2)
        nearest = np.argmin(distance, axis=1)
        exact = np.flatnonzero(distance[np.arange(len(query)), nearest] <= _SAME ** 2)
        out[exact] = 0.0
        out[exact, nearest[exact]] = 1.0
        return out

    @property
    def mix_gain(self) -> float:
        """Gain (≤ 1) on the whole mix so that it never peaks higher than the loudest single loop.

        Equal-power gains keep the mix's power but not its peak: where loops align, the mix of
        three can reach √3 times a loop's peak. For each triangle (or neighbours on a line) the
        highest peak over every choice of weights is, at each instant, the norm of the loops'
        positive (or negative) values; this gain brings the highest of those down to the
        loudest loop's peak (normalised below full scale; full scale, should a loop be louder).
        1 for a single point. Computed once.
        """
        cached = self.__dict__.get("_mix_gain")
        if cached is None:
            cached = _mix_gain(self)
            self.__dict__["_mix_gain"] = cached
        return cached

    def _geo(self) -> _Geometry:
        if self._geometry is None:
            object.__setattr__(self, "_geometry", _geometry(self.coordinates / self.scale))
        return self._geometry

    # --- JSON -----------------------------------------------------------------------------

    def to_json(self) -> dict:
        """``{"full_pressure_force_n", "reference", "points": [GridPoint.to_json(), ...]}``
        (``profile.json``'s ``grid`` section)."""
        return {"full_pressure_force_n": self.full_pressure_force_n,
                "reference": self.reference,
                "points": [point.to_json() for point in self.points]}

    @classmethod
    def from_json(cls, data: dict, **origin) -> VibrationGrid:
        """A grid from :meth:`to_json`'s form; ``origin`` sets ``notes`` and ``provenance``.

        Raises:
            ParameterError: unknown or missing fields, or bad values.
        """
        if not isinstance(data, dict):
            raise ParameterError("grid", f"must be a JSON object, got {type(data).__name__}")
        unknown = sorted(set(data) - {"full_pressure_force_n", "reference", "points"})
        if unknown:
            raise ParameterError("grid", f"unknown field(s) {', '.join(unknown)}")
        raw = data.get("points")
        if not isinstance(raw, list):
            raise ParameterError("points", "must be a list of points")
        points = []
        for index, item in enumerate(raw[:MAX_GRID_POINTS + 1]):
            if not isinstance(item, dict) or set(item) != {"speed_mm_s", "force_n", "tactile"}:
                raise ParameterError("points", f"point {index} must hold exactly speed_mm_s, "
                                               f"force_n and tactile")
            points.append(GridPoint(item["speed_mm_s"], item["force_n"],
                                    TactilePattern.from_json(item["tactile"])))
        return cls(tuple(points), data.get("full_pressure_force_n", FULL_PRESSURE_FORCE_N),
                   data.get("reference", 0), **origin)


def _largest_power(pattern: TactilePattern) -> float:
    """The largest mean-square power of a sub-pattern (full scale²): the sinusoids' a²/2 and
    the residual's band powers."""
    sines = max(sum(c.amplitude ** 2 / 2 for c in sub) for sub in pattern.subpatterns)
    noise = 0.0 if pattern.residual is None else float(np.max(pattern.residual.powers))
    return sines + noise


def _mix_gain(grid: VibrationGrid) -> float:
    if len(grid.points) == 1:
        return 1.0
    loops = np.stack([np.asarray(p.samples, dtype=np.float64) for p in grid.patterns])
    loudest = float(np.max(np.abs(loops)))
    allowed = min(loudest, 1.0)  # a loop above full scale (edited JSON) is brought down too
    geo = grid._geo()
    if geo.kind == "line":  # only neighbours along the line mix
        groups = [[int(a), int(b)] for a, b in zip(geo.order[:-1], geo.order[1:])]
    else:  # only a triangle's corners mix (outside the hull: an edge's, within a triangle)
        groups = [list(tri) for tri in geo.triangles]
    highest = loudest
    for group in groups:
        # At each instant the largest Σ sqrt(w_i) x_i over weights summing to 1 is the norm of
        # the positive x_i (Cauchy-Schwarz), and likewise below zero: the exact worst case.
        part = loops[group]
        for signed in (np.clip(part, 0.0, None), np.clip(-part, 0.0, None)):
            highest = max(highest, float(np.sqrt(np.max(np.sum(signed ** 2, axis=0)))))
    return allowed / highest if highest > 0 else 1.0


def _shape(pattern: TactilePattern) -> str:
    count = len(pattern.subpatterns)
    return (f"{count} sub-pattern{'s' if count != 1 else ''} × {pattern.subpattern_ms:g} ms at "
            f"{pattern.rate} Hz")


def _finite_array(name: str, values) -> np.ndarray:
    try:
        array = np.asarray(values, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise ParameterError(name, "must be numbers") from None
    if not np.all(np.isfinite(array)):
        raise ParameterError(name, "must be finite numbers")
    return array


def _geometry(scaled: np.ndarray) -> _Geometry:
    """Triangulate the scaled points, or find the line they lie on."""
    no_triangles = np.zeros((0, 3), dtype=np.int64)
    if len(scaled) == 1:
        return _Geometry("single", scaled, no_triangles)
    centred = scaled - scaled.mean(axis=0)
    _, singular, rows = np.linalg.svd(centred, full_matrices=False)
    if len(scaled) >= 3 and singular[1] > _LINE * singular[0]:
        from scipy.spatial import Delaunay, QhullError

        try:
            delaunay = Delaunay(scaled)
        except QhullError:  # flat after all, for qhull's precision: treated as a line
            delaunay = None
        if delaunay is not None:
            if len(delaunay.coplanar):  # cannot happen for points _APART apart; be sure
                raise ParameterError("points", "some points are too close to be triangulated")
            return _Geometry("plane", scaled, delaunay.simplices.astype(np.int64), delaunay,
                             delaunay.convex_hull.astype(np.int64))
    direction = rows[0]
    along = centred @ direction
    order = np.argsort(along, kind="stable")
    return _Geometry("line", scaled, no_triangles, origin=scaled.mean(axis=0),
                     direction=direction, order=order, along=along[order])


def _along_line(geo: _Geometry, query: np.ndarray, out: np.ndarray) -> None:
    """Linear interpolation between neighbours along the line, clamped to its ends."""
    along = np.clip((query - geo.origin) @ geo.direction, geo.along[0], geo.along[-1])
    segment = np.clip(np.searchsorted(geo.along, along, side="right") - 1, 0, len(geo.along) - 2)
    start, stop = geo.along[segment], geo.along[segment + 1]
    fraction = np.clip((along - start) / (stop - start), 0.0, 1.0)
    rows = np.arange(len(query))
    out[rows, geo.order[segment]] += 1.0 - fraction
    out[rows, geo.order[segment + 1]] += fraction


def _in_plane(geo: _Geometry, query: np.ndarray, out: np.ndarray) -> None:
    """Barycentric weights in the triangle holding each query; a query outside the hull is
    moved to the nearest point of the hull first (its weights are then those of that edge)."""
    simplex = geo.delaunay.find_simplex(query)
    inside = np.flatnonzero(simplex >= 0)
    if len(inside):
        transform = geo.delaunay.transform[simplex[inside]]  # (n, 3, 2)
        first = np.einsum("nij,nj->ni", transform[:, :2], query[inside] - transform[:, 2])
        bary = np.clip(np.concatenate([first, 1.0 - first.sum(axis=1, keepdims=True)], axis=1),
                       0.0, None)
        corners = geo.triangles[simplex[inside]]
        out[inside[:, None], corners] = bary / bary.sum(axis=1, keepdims=True)
    outside = np.flatnonzero(simplex < 0)
    if len(outside):
        a, b = geo.scaled[geo.hull[:, 0]], geo.scaled[geo.hull[:, 1]]  # (H, 2)
        edge = b - a
        q = query[outside][:, None, :]  # (n, 1, 2)
        t = np.clip(np.sum((q - a) * edge, axis=2) / np.sum(edge * edge, axis=1), 0.0, 1.0)
        gap = np.sum((a + t[..., None] * edge - q) ** 2, axis=2)  # (n, H)
        best = np.argmin(gap, axis=1)
        fraction = t[np.arange(len(outside)), best]
        out[outside, geo.hull[best, 0]] += 1.0 - fraction
        out[outside, geo.hull[best, 1]] += fraction


# --- building grids ----------------------------------------------------------------------------
# The tactile pipeline (scipy, soundfile) is imported inside these functions: this module stays
# light for the profile schema.

HATT_SECONDS = 4.0
"""Seconds of vibration synthesised at each HaTT vertex (the pattern's stretch is 1.5 s of it,
away from the ends)."""
Progress = Callable[[int, int], None]


def central_point(coordinates: np.ndarray) -> int:
    """The index of the point nearest the median speed and median force of ``coordinates``
    ((P, 2): speed mm/s, force N), both axes divided by their range; the first of equals."""
    coordinates = np.asarray(coordinates, dtype=np.float64)
    span = np.ptp(coordinates, axis=0)
    scaled = coordinates / np.where(span > 0, span, 1.0)
    distance = np.sum((scaled - np.median(scaled, axis=0)) ** 2, axis=1)
    return int(np.argmin(distance))


def _check_point(index: int, speed_mm_s: object, force_n: object) -> tuple[float, float]:
    """A point's speed and force, checked before anything is built for it."""
    values = []
    for name, value, limit in (("speed_mm_s", speed_mm_s, MAX_SPEED_MM_S),
                               ("force_n", force_n, MAX_FORCE_N)):
        if not is_number(value) or not math.isfinite(value) or not 0 <= value <= limit:
            raise ParameterError("points", f"point {index}: {name} must be a finite number from "
                                           f"0 to {limit:g}, got {value!r}")
        values.append(float(value))
    return values[0], values[1]


def _grid(patterns: list[tuple[float, float, TactilePattern]], reference: int | None,
          full_pressure_force_n: float, **origin) -> VibrationGrid:
    coordinates = np.array([[s, f] for s, f, _ in patterns])
    chosen = central_point(coordinates) if reference is None else reference
    return VibrationGrid(tuple(GridPoint(s, f, p) for s, f, p in patterns),
                         full_pressure_force_n, chosen, **origin)


def grid_from_recordings(points: Sequence[tuple[float, float, Recording]],
                         actuator: Actuator | str, params: TactileParams | None = None, *,
                         reference: int | None = None,
                         full_pressure_force_n: float = FULL_PRESSURE_FORCE_N,
                         progress: Progress | None = None, **options) -> VibrationGrid:
    """A vibration grid from recordings made at (speed, force) points.

    Each recording goes through :func:`~realpen.tactile.build.build_pattern` with the same
    ``params`` and ``actuator``.

    Args:
        points: ``(speed_mm_s, force_n, recording)`` per point: speed in mm/s and force in N
            (finite, ≥ 0, distinct pairs), a :class:`~realpen.io.recording.Recording`.
        actuator: the actuator (or its spec string) every pattern is equalised for.
        params: the tactile pipeline's parameters (default: condition B's); ``options``
            override its fields, as in :func:`~realpen.tactile.build.build_pattern`.
        reference: the index of the point whose pattern becomes the profile's ``tactile``
            section (default: :func:`central_point`).
        full_pressure_force_n: the force in N at page pressure 1.
        progress: called as ``progress(points_done, points)``.

    Returns:
        The grid; its ``provenance["sources"]`` lists the recordings, in point order.

    Raises:
        ParameterError: no points or more than :data:`~realpen.checks.MAX_GRID_POINTS`,
            a bad speed, force, ``reference`` or ``full_pressure_force_n`` (all checked
            before any pattern is built).
        RealPenError: a problem with a recording, naming it.
    """
    from realpen.io.recording import Recording
    from realpen.tactile.build import build_pattern

    if isinstance(points, (str, bytes)) or not len(points):
        raise ParameterError("points", "a grid needs at least one (speed, force, recording)")
    if len(points) > MAX_GRID_POINTS:
        raise ParameterError("points", f"{len(points):,} points; a grid holds at most "
                                       f"{MAX_GRID_POINTS}")
    checked = []
    for index, item in enumerate(points):
        if not isinstance(item, (tuple, list)) or len(item) != 3 \
                or not isinstance(item[2], Recording):
            raise ParameterError("points", f"point {index} must be (speed_mm_s, force_n, "
                                           f"Recording)")
        checked.append((*_check_point(index, item[0], item[1]), item[2]))
    _check_grid_options(reference, len(checked), full_pressure_force_n)
    params = _params(params, options)
    patterns = []
    for index, (speed, force, recording) in enumerate(checked):
        try:
            patterns.append((speed, force, build_pattern(recording, actuator, params)))
        except ParameterError as error:  # which point's recording asked too much of a parameter
            raise ParameterError(error.parameter, f"{error.problem} (point {index} at "
                                                  f"{speed:g} mm/s, {force:g} N: "
                                                  f"{recording.source})") from None
        if progress is not None:
            progress(index + 1, len(checked))
    sources = [{"role": "vibration", "name": Path(recording.source).name,
                "sha256": recording.sha256} for _, _, recording in checked]
    return _grid(patterns, reference, full_pressure_force_n, provenance={"sources": sources})


def _params(params: TactileParams | None, options: dict) -> TactileParams:
    from realpen.tactile.conditions import TactileParams

    if params is None:
        return TactileParams(**options)
    if not isinstance(params, TactileParams):
        raise ParameterError("params", f"must be TactileParams, got {type(params).__name__}")
    return params.updated(**options) if options else params


def _check_grid_options(reference: int | None, count: int, full_pressure_force_n: float) -> None:
    """What the grid will refuse, refused before any pattern is built."""
    if check_magnitude("full_pressure_force_n", full_pressure_force_n, MAX_FORCE_N) <= 0:
        raise ParameterError("full_pressure_force_n", "must be > 0, got 0")
    if reference is not None and (isinstance(reference, bool)
                                  or not isinstance(reference, (int, np.integer))
                                  or not 0 <= reference < count):
        raise ParameterError("reference", f"must be a point's index, 0 to {count - 1}, got "
                                          f"{reference!r}")


def grid_from_hatt(models: HattModelSet, actuator: Actuator | str,
                   params: TactileParams | None = None, *, duration_s: float = HATT_SECONDS,
                   seed: int = 0, reference: int | None = None,
                   full_pressure_force_n: float = FULL_PRESSURE_FORCE_N,
                   progress: Progress | None = None, **options) -> VibrationGrid:
    """A vibration grid from every vertex of a HaTT texture model.

    At each vertex's (speed mm/s, force N), ``duration_s`` seconds of stylus vibration are
    synthesised from its own model (:func:`realpen.datasets.hatt.synthesize`, seeded) and made
    into a pattern with ``params`` for ``actuator``. Vertices at speed 0 or force 0 are left
    out (a stylus that does not slide, or does not touch, does not vibrate; the synthesis
    there is silence or noise nobody feels), and a note says how many.

    Args:
        models: the texture (:func:`realpen.datasets.hatt.load_hatt`).
        actuator: the actuator (or its spec string) every pattern is equalised for.
        params: the tactile pipeline's parameters (default: condition B's); ``options``
            override its fields (``cap_db=``, ``model=``, …).
        duration_s: seconds synthesised per vertex.
        seed: seed of the synthesis (the same at every vertex).
        reference: the index, among the points kept, of the reference point (default:
            :func:`central_point`).
        full_pressure_force_n: the force in N at page pressure 1.
        progress: called as ``progress(points_done, points)``.

    Returns:
        The grid; ``provenance["sources"]`` names the model file, ``provenance["model"]``
        says how the vibration was made.

    Raises:
        ParameterError: a bad ``duration_s``, ``seed``, ``reference`` or
            ``full_pressure_force_n``.
        RealPenError: no vertex with speed and force above 0, or a vertex whose vibration
            makes no pattern (naming the model file and the vertex).
    """
    from realpen.datasets.hatt import synthesize
    from realpen.tactile.build import build_pattern

    usable = [index for index, (speed, force) in enumerate(models.vertices)
              if speed > 0 and force > 0]
    if not usable:
        raise fail(models.source, "no model vertex has a speed and a force above 0")
    if len(usable) > MAX_GRID_POINTS:
        raise fail(models.source, f"{len(usable)} model vertices; a grid holds at most "
                                  f"{MAX_GRID_POINTS}")
    _check_grid_options(reference, len(usable), full_pressure_force_n)
    params = _params(params, options)
    patterns = []
    for done, index in enumerate(usable):
        speed, force = (float(v) for v in models.vertices[index])
        recording = synthesize(models, speed, force, duration_s, seed=seed)
        try:
            pattern = build_pattern(recording, actuator, params)
        except ParameterError:
            raise
        except RealPenError as error:
            raise fail(models.source, f"model {index + 1} ({speed:g} mm/s, {force:g} N): "
                                      f"{str(error).removeprefix(recording.source + ': ')}") \
                from None
        patterns.append((speed, force, pattern))
        if progress is not None:
            progress(done + 1, len(usable))
    left_out = len(models.vertices) - len(usable)
    notes = ((f"{left_out} of the {len(models.vertices)} HaTT model vertices are at speed 0 "
              f"or force 0 and were left out (no sliding vibration there); outside the "
              f"others the nearest edge of the grid is felt",) if left_out else ())
    name = Path(models.source).name
    model = {"hatt": models.material, "file": name, "duration_s": float(duration_s),
             "seed": int(seed), "vertices": len(usable), "vertices_left_out": left_out}
    return _grid(patterns, reference, full_pressure_force_n, notes=notes,
                 provenance={"sources": [{"role": "hatt model", "name": name,
                                          "sha256": models.sha256}],
                             "model": model})
