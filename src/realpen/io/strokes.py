"""The stroke sample: one pen event, the one definition every layer uses.

A stroke sample is what the pen reports at one instant while it writes:

- ``t`` (s): time; on the page's clock (``performance.now() / 1000``) in the live app, since
  pen down in the store, as written in a trajectory CSV;
- ``x``, ``y`` (mm): position across and down the writing surface, from its top-left corner;
- ``pressure`` (0–1): normalised pressure; 0 means the pen is lifted (a mouse reports 0.5);
- ``tilt_x``, ``tilt_y`` (degrees, −90 to 90): Pointer Events ``tiltX`` and ``tiltY``;
- ``speed`` (mm/s): pen speed, as the live page measures it over 20 ms (see
  :mod:`realpen.sound.stroke`).

:class:`StrokeSample` is a strict pydantic model: a number is a number (``"0.5"`` is not a
pressure, ``true`` is not a time), nothing else is accepted, NaN and infinity are refused. The
live app's WebSocket schema (:class:`realpen.live.messages.Sample` *is* this class), the stroke
store's columns (:data:`SAMPLE_FIELDS`, in this order) and the columnar
:class:`realpen.motion.trajectory.Trajectory` (its columns and value ranges) all come from here.

This module imports pydantic only, so the WebSocket schema can load without numpy's heavier
neighbours (scipy, soundfile).
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["StrokeSample", "SAMPLE_FIELDS", "TRAJECTORY_FIELDS",
           "PRESSURE_RANGE", "TILT_RANGE_DEG", "POSITION_RANGE_MM", "TIME_RANGE_S",
           "SPEED_RANGE_MM_S", "Time", "Millimetres"]

TIME_RANGE_S = (-1e9, 1e12)          # s: any clock a page or a file uses
POSITION_RANGE_MM = (-1e6, 1e6)      # mm: a kilometre either way is no writing surface
PRESSURE_RANGE = (0.0, 1.0)          # normalised; 0 = lifted
TILT_RANGE_DEG = (-90.0, 90.0)       # degrees (Pointer Events)
SPEED_RANGE_MM_S = (0.0, 1e6)        # mm/s

Time = Annotated[float, Field(ge=TIME_RANGE_S[0], le=TIME_RANGE_S[1])]
"""A time in s (pydantic field type)."""
Millimetres = Annotated[float, Field(ge=POSITION_RANGE_MM[0], le=POSITION_RANGE_MM[1])]
"""A position in mm (pydantic field type)."""


class StrokeSample(BaseModel):
    """One pen sample (a coalesced pointer event); see the module doc for the units.

    Attributes:
        t: time in s.
        x, y: position in mm.
        pressure: normalised pressure, 0–1 (0: lifted).
        tilt_x, tilt_y: tilt in degrees, −90–90 (default 0: upright, or not reported).
        speed: pen speed in mm/s, ≥ 0.

    Example:
        >>> StrokeSample(t=0.01, x=12.5, y=40.0, pressure=0.5, speed=48.0).as_row()
        (0.01, 12.5, 40.0, 0.5, 0.0, 0.0, 48.0)
    """

    # strict: JSON types are taken as they are — "0.5" is not a pressure, 1 is not a boolean
    # (a number field still takes a JSON integer: 0 is 0.0).
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, strict=True)

    t: Time
    x: Millimetres
    y: Millimetres
    pressure: float = Field(ge=PRESSURE_RANGE[0], le=PRESSURE_RANGE[1])
    tilt_x: float = Field(0.0, ge=TILT_RANGE_DEG[0], le=TILT_RANGE_DEG[1])
    tilt_y: float = Field(0.0, ge=TILT_RANGE_DEG[0], le=TILT_RANGE_DEG[1])
    speed: float = Field(ge=SPEED_RANGE_MM_S[0], le=SPEED_RANGE_MM_S[1])

    def as_row(self) -> tuple[float, ...]:
        """The values in :data:`SAMPLE_FIELDS` order (s, mm, mm, 0–1, degrees, degrees, mm/s)."""
        return tuple(getattr(self, name) for name in SAMPLE_FIELDS)

    def __repr__(self) -> str:
        return (f"StrokeSample(t={self.t:.6g} s, x={self.x:.6g} mm, y={self.y:.6g} mm, "
                f"pressure={self.pressure:.4g}, tilt=({self.tilt_x:.4g}, {self.tilt_y:.4g}) deg, "
                f"speed={self.speed:.6g} mm/s)")


SAMPLE_FIELDS: tuple[str, ...] = tuple(StrokeSample.model_fields)
"""The fields of a stroke sample, in order: the stroke store's sample columns."""

TRAJECTORY_FIELDS: tuple[str, ...] = SAMPLE_FIELDS[:4]
"""The columns a trajectory CSV must have (``t, x, y, pressure``); speed is computed from them."""
