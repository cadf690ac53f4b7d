"""What a stroke feels like: a pen trajectory through a :class:`~realpen.tactile.grid.VibrationGrid`.

The tactile counterpart of :func:`realpen.sound.stroke.render_stroke`, following the live page
(``live/static/writer.js``, ``audio.js``) so that the drive signal can be looked at and tested
offline:

- the tactile loop is gated as the page gates it: its gain is the Eq. 1 gain of the coupling
  over ``a_max`` (full drive at ``a_max``), smoothed by the coupling's one-pole, so it plays
  while the pen moves on the surface and falls silent when it is lifted or stops
  (:func:`realpen.motion.control.control_signals`, the same speed meter and pen-down rule);
- with several points, every point's loop plays, all started together at the stroke's first
  event, point i's through a gain that follows ``sqrt(w_i)`` at the pen's speed and force
  (force = pressure × ``full_pressure_force_n``), smoothed by the same one-pole. As on the page,
  the point gains start at the reference point (gain 1, the others 0), change at each event
  with the pen down and hold while it is lifted;
- a single pattern (or a one-point grid) is the loop times the gate, exactly the page's one
  tactile loop.

The page's loop runs from when the pen was loaded, so its phase at a stroke's start is
whatever it is; here the loops start with the stroke.
"""

from __future__ import annotations

import numpy as np

from realpen.checks import MAX_RATE_HZ, MAX_RENDER_FRAMES, require_number
from realpen.errors import ParameterError
from realpen.motion.control import control_signals, render_frames
from realpen.motion.coupling import Coupling
from realpen.motion.trajectory import Trajectory
from realpen.tactile.grid import VibrationGrid
from realpen.tactile.pattern import TactilePattern

__all__ = ["render_tactile_stroke", "point_targets"]


def _as_grid(grid_or_pattern) -> VibrationGrid:
    if isinstance(grid_or_pattern, VibrationGrid):
        return grid_or_pattern
    if isinstance(grid_or_pattern, TactilePattern):
        return VibrationGrid.single(grid_or_pattern)
    raise ParameterError("grid_or_pattern", f"must be a VibrationGrid or a TactilePattern, got "
                                            f"{type(grid_or_pattern).__name__}")


def point_targets(grid: VibrationGrid, trajectory: Trajectory) -> np.ndarray:
    """The target gain of each point's loop at each event, before smoothing.

    ``sqrt(w_i)`` at the event's speed (mm/s, the page's meter) and force (pressure ×
    ``grid.full_pressure_force_n``, N) while the pen is down; a lifted event keeps the
    previous targets; before the first pen-down event, the reference point alone.

    Returns:
        (events, points) float64.
    """
    down = trajectory.pressure > 0
    targets = np.zeros((len(trajectory), len(grid.points)))
    targets[:, grid.reference] = 1.0
    if down.any():
        speed = trajectory.speed()[down]
        force = trajectory.pressure[down] * grid.full_pressure_force_n
        # Each event takes the targets of the newest pen-down event up to it.
        newest = np.maximum.accumulate(np.where(down, np.arange(len(down)), -1))
        held = newest >= 0
        targets[held] = np.sqrt(grid.weight_matrix(speed, force))[np.cumsum(down)[held] - 1]
    return targets


def render_tactile_stroke(grid_or_pattern: VibrationGrid | TactilePattern, trajectory: Trajectory,
                          rate: float | None = None, *, coupling: Coupling | None = None
                          ) -> np.ndarray:
    """The tactile drive signal along a recorded stroke (see the module doc).

    Args:
        grid_or_pattern: a :class:`~realpen.tactile.grid.VibrationGrid` (e.g.
            :attr:`realpen.profile.bundle.PenProfile.grid`) or one
            :class:`~realpen.tactile.pattern.TactilePattern`.
        trajectory: the stroke (``t`` s, ``x``/``y`` mm, ``pressure`` 0–1), e.g. from
            :func:`realpen.motion.trajectory.load_trajectory`.
        rate: output rate in Hz (default: the patterns' own rate). Loops are rendered at it;
            at the patterns' own rate their :attr:`~TactilePattern.samples` are used (a
            profile's ``tactile.wav`` for its reference pattern).
        coupling: the Eq. 1 constants and smoother (default
            ``Coupling()``, :class:`~realpen.motion.coupling.Coupling`; a profile's is ``profile.coupling``).

    Returns:
        float64 array at ``rate`` Hz covering the stroke plus five smoothing time constants
        (as the sound's render), full scale ±1 at full drive.

    Raises:
        ParameterError: a bad ``rate`` (not positive, too low for the components, or a render
            of more than :data:`~realpen.checks.MAX_RENDER_FRAMES` samples, or loops
            of more than that in all).

    Example:
        >>> from realpen.tactile.pattern import Component
        >>> from realpen.motion.trajectory import Trajectory
        >>> stroke = Trajectory.checked([0, 0.5, 1.0], [0, 25, 50], [0, 0, 0], [0.5] * 3)
        >>> pattern = TactilePattern([[Component(175.0, 0.5)]])
        >>> render_tactile_stroke(pattern, stroke).shape
        (8201,)
    """
    grid = _as_grid(grid_or_pattern)
    if not isinstance(trajectory, Trajectory):
        raise ParameterError("trajectory", f"must be a Trajectory, got "
                                           f"{type(trajectory).__name__}")
    coupling = Coupling() if coupling is None else coupling
    rate = grid.rate if rate is None else rate
    if isinstance(rate, (np.integer, np.floating)):
        rate = rate.item()
    require_number("rate", rate, minimum=0.0, inclusive=False, maximum=MAX_RATE_HZ)
    frames = render_frames(trajectory, coupling, rate)
    loop_frames = grid.points[0].pattern.frames_at(rate)
    if frames > MAX_RENDER_FRAMES or loop_frames * len(grid.points) > MAX_RENDER_FRAMES:
        raise ParameterError("rate", f"a {trajectory.duration_s:g} s stroke with "
                                     f"{len(grid.points)} loop(s) of {loop_frames:,} samples "
                                     f"at {rate:g} Hz is too much to render (at most "
                                     f"{MAX_RENDER_FRAMES:,} samples each; a lower rate or a "
                                     f"shorter stroke)")
    _, gate, _ = control_signals(trajectory, coupling, rate)
    gate = gate / coupling.a_max
    position = np.arange(frames) % loop_frames
    if len(grid.points) == 1:
        return gate * _loop(grid.points[0].pattern, rate)[position]
    times = trajectory.t - trajectory.t[0]
    event = np.searchsorted(times, np.arange(frames) / rate, side="right") - 1
    targets = point_targets(grid, trajectory)
    mix = np.zeros(frames)
    for index, point in enumerate(grid.points):
        if not targets[:, index].any():  # never heard: not rendered
            continue
        initial = 1.0 if index == grid.reference else 0.0
        gain = coupling.smooth(targets[event, index], rate, initial=initial)
        mix += gain * _loop(point.pattern, rate)[position]
    return gate * grid.mix_gain * mix


def _loop(pattern: TactilePattern, rate: float) -> np.ndarray:
    """One loop at ``rate`` Hz: the pattern's own samples at its rate, else rendered."""
    return np.asarray(pattern.samples if rate == pattern.rate else pattern.render(rate),
                      dtype=np.float64)
