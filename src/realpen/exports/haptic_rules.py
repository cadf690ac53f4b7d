"""The rules a Lofelt / Meta ``.haptic`` file (data model v1) must keep, checked as Lofelt does.

From Lofelt's data model (``core/datamodel`` of Lofelt/NiceVibrations: ``src/lib.rs`` reads the
version, ``src/v1.rs`` deserialises and validates), in the order Lofelt checks them:

- ``version.major`` is 1 (``minor`` and ``patch`` default to 0; a newer minor version is read,
  its unknown fields ignored). A file without ``version`` is v0 (``.vij``), which RealPen does
  not read.
- ``signals.continuous.envelopes.amplitude`` is present and not empty; ``frequency`` is
  optional. Each amplitude breakpoint has a numeric ``time`` and ``amplitude`` and may have an
  ``emphasis`` with numeric ``amplitude`` and ``frequency``; each frequency breakpoint has a
  numeric ``time`` and ``frequency``. ``metadata`` is optional; its fields are text
  (``tags`` a list of text).
- For each amplitude breakpoint in turn: the amplitude lies in [0, 1]; its time is not before
  the previous breakpoint's (the first's not before 0); an emphasis amplitude and frequency lie
  in [0, 1] and the emphasis amplitude is at least the breakpoint's amplitude.
- Then for each frequency breakpoint: the frequency lies in [0, 1]; times do not decrease
  (from 0).

Every refusal is one :class:`~realpen.errors.RealPenError` naming the file, the field and the
rule, e.g. ``"x.haptic: signals.continuous.envelopes.amplitude[3].time: breakpoint times must
not decrease (0.2 after 0.3) (Lofelt v1)"``.
"""

from __future__ import annotations

from realpen.exports.readers.fields import array, integer, member, number, problem, text, where

__all__ = ["RULE", "ENVELOPES", "check_haptic"]

RULE = "(Lofelt v1)"
ENVELOPES = "signals.continuous.envelopes"


def _required(obj: object, key: str, source: object, at: str) -> object:
    """``obj[key]``, refused by name when missing."""
    if isinstance(obj, dict) and key not in obj:
        raise problem(source, where(at, key), f"is missing: Lofelt v1 requires it {RULE}")
    return member(obj, key, source, at)


def _unit(value: object, source: object, at: str) -> float:
    """A number in [0, 1]."""
    value = number(value, source, at)
    if not 0.0 <= value <= 1.0:
        raise problem(source, at, f"must be from 0 to 1, got {value:g} {RULE}")
    return value


def _time(value: object, previous: float, source: object, at: str) -> float:
    """A breakpoint time not before ``previous`` (0 for the first breakpoint)."""
    value = number(value, source, at)
    if value < previous:
        raise problem(source, at, f"breakpoint times must not be negative, got {value:g} {RULE}"
                      if previous == 0.0 else
                      f"breakpoint times must not decrease ({value:g} after {previous:g}) {RULE}")
    return value


def _version(document: dict, source: object) -> None:
    if "version" not in document:
        raise problem(source, "version", "is missing: a file without one is Lofelt v0 (.vij), "
                                         "which is not read; convert it to v1")
    version = document["version"]
    major = integer(_required(version, "major", source, "version"), source, "version.major",
                    low=0)
    for part in ("minor", "patch"):
        if part in version:
            integer(version[part], source, where("version", part), low=0)
    if major == 0:
        raise problem(source, "version.major", "0 is Lofelt v0 (.vij), which is not read; "
                                               "convert it to v1")
    if major != 1:
        raise problem(source, "version.major", f"must be 1, got {major}: version {major} is "
                                               f"not supported {RULE}")


def _metadata(document: dict, source: object) -> None:
    metadata = document.get("metadata")
    if metadata is None:
        return
    member(metadata, "editor", source, "metadata", required=False)  # an object, if present
    for key in ("editor", "author", "source", "project", "description"):
        if key in metadata:
            text(metadata[key], source, where("metadata", key))
    if "tags" in metadata:
        for index, tag in enumerate(array(metadata["tags"], source, "metadata.tags")):
            text(tag, source, where("metadata.tags", index))


def check_haptic(document: object, source: object) -> dict:
    """Check a parsed ``.haptic`` document against the Lofelt v1 rules (module docstring).

    Args:
        document: the parsed JSON.
        source: the file (or export name) to name in a refusal.

    Returns:
        ``document``, unchanged.

    Raises:
        RealPenError: one line naming ``source``, the field and the rule broken.

    Example:
        >>> check_haptic({"version": {"major": 1}, "signals": {"continuous": {"envelopes": {
        ...     "amplitude": [{"time": 0.1, "amplitude": 0.5},
        ...                   {"time": 0.0, "amplitude": 0.2}]}}}}, "x.haptic")
        Traceback (most recent call last):
        ...
        realpen.errors.RealPenError: x.haptic: signals.continuous.envelopes.amplitude[1].time: \
breakpoint times must not decrease (0 after 0.1) (Lofelt v1)
    """
    if not isinstance(document, dict):
        raise problem(source, "", f"must hold a JSON object {RULE}")
    _version(document, source)
    _metadata(document, source)
    signals = _required(document, "signals", source, "")
    continuous = _required(signals, "continuous", source, "signals")
    envelopes = _required(continuous, "envelopes", source, "signals.continuous")
    at = where(ENVELOPES, "amplitude")
    amplitude = array(_required(envelopes, "amplitude", source, ENVELOPES), source, at)
    if not amplitude:
        raise problem(source, at, f"the amplitude envelope must not be empty {RULE}")
    previous = 0.0
    for index, point in enumerate(amplitude):
        here = where(at, index)
        level = _unit(_required(point, "amplitude", source, here), source, where(here, "amplitude"))
        previous = _time(_required(point, "time", source, here), previous, source,
                         where(here, "time"))
        emphasis = point.get("emphasis")
        if emphasis is None:
            continue
        there = where(here, "emphasis")
        strength = _unit(_required(emphasis, "amplitude", source, there), source,
                         where(there, "amplitude"))
        _unit(_required(emphasis, "frequency", source, there), source, where(there, "frequency"))
        if strength < level:
            raise problem(source, where(there, "amplitude"),
                          f"an emphasis amplitude must be at least its breakpoint's amplitude "
                          f"({strength:g} < {level:g}) {RULE}")
    frequency = envelopes.get("frequency")
    if frequency is not None:
        at = where(ENVELOPES, "frequency")
        previous = 0.0
        for index, point in enumerate(array(frequency, source, at)):
            here = where(at, index)
            _unit(_required(point, "frequency", source, here), source, where(here, "frequency"))
            previous = _time(_required(point, "time", source, here), previous, source,
                             where(here, "time"))
    return document
