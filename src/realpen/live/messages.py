"""Every WebSocket message of the live app, as pydantic schemas (protocol 1).

The page sends JSON text frames, one message each, told apart by ``type``:

``hello``     once per connection: who is talking (``client``), the ``protocol`` number, and
              the page's own id (``page``, optional): the same across its reconnects, so that
              what it resends after a reconnect is recognised and stored once;
``pen_down``  a stroke starts: the pen (profile name and content version), the modality
              (:data:`MODALITIES`; the old name ``auditory-tactile`` is still taken, as
              ``audio-tactile``), the ink (visible or hidden), the pointer type and the page's
              calibration (px/mm);
              in a study, the study session and trial number it belongs to (``study_session``,
              ``trial``; optional, both or neither);
``samples``   a batch of the stroke's samples (the coalesced pointer events of one event),
              with ``index``, the number of its first sample within the stroke (optional; a
              sample number already stored is not stored again);
``gain``      the stroke's new target gain (Eq. 1 before smoothing), for the pen's actuator;
``pen_up``    the stroke ends.

Every message carries ``seq``, the page's message counter, and the server replies to each with
``ack`` (echoing ``seq``, with the server's receive time) or ``error`` (a ``code`` and a
one-line ``message``; ``seq`` when it could be read). A message larger than
:data:`MAX_MESSAGE_BYTES` or holding more than :data:`MAX_SAMPLES` samples is refused.

A page keeps every message until it is acknowledged and, after a reconnect, sends again those
that were not: pen-downs, samples and pen-ups are idempotent (by page, stroke and sample
number), so nothing is lost and nothing is stored twice.

Types are strict: a number is a JSON number (an integer where one is counted: ``seq``,
``stroke``), a flag is ``true`` or ``false``, text is a string; nothing is coerced.

Integer ranges are the store's own (:mod:`realpen.io.limits`), so that whatever the schema takes
a store can hold: ``stroke``, ``index`` and the number of a batch's last sample
(``index + len(samples) - 1``) are 0 to :data:`~realpen.io.limits.MAX_STORED_INT`
(2,147,483,647), ``study_session`` and ``trial`` 1 to that; ``seq``, echoed in the reply but never
stored, is 0 to :data:`~realpen.io.limits.MAX_JSON_INT` (2**53). A number out of its range is
refused like any other schema violation (``invalid_message``: not stored, not to be sent again).

Units: ``t`` in seconds on the page's clock (``performance.now() / 1000``); ``x``, ``y`` in mm
from the writing surface's top-left corner (CSS pixels over the calibration); ``pressure``
normalised 0–1 (a mouse reports the constant 0.5); ``tilt_x``, ``tilt_y`` in degrees
(−90–90, Pointer Events); ``speed`` in mm/s as the page computed it for Eq. 1. A sample is the
one stroke-sample definition, :class:`realpen.io.strokes.StrokeSample` (:class:`Sample` is that
class), which the stroke store and stroke rendering use as well.

This module imports pydantic, :mod:`realpen.io.strokes`, :mod:`realpen.io.limits`, the profile
schema's name rule, :mod:`realpen.defaults`, :mod:`realpen.errors` and :mod:`realpen.validation`
only: loading the WebSocket schema loads neither scipy nor soundfile.
"""

from __future__ import annotations

import json
from typing import Annotated, Literal

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    TypeAdapter,
    ValidationError,
    model_validator,
)

from realpen.defaults import MODALITIES, modality_name
from realpen.errors import RealPenError
from realpen.io.limits import MAX_JSON_INT, MAX_STORED_INT
from realpen.io.strokes import StrokeSample, Time
from realpen.profile.schema import NAME_PATTERN  # pydantic-only: the name rule's one home
from realpen.validation import validation_line

__all__ = ["PROTOCOL", "MAX_MESSAGE_BYTES", "MAX_SAMPLES", "MODALITIES", "NAME_PATTERN",
           "PAGE_PATTERN",
           "Sample", "Hello", "PenDown", "Samples", "Gain", "PenUp", "ClientMessage",
           "CLIENT_MESSAGE", "Ack", "Error", "MessageError", "parse_message"]

PROTOCOL = 1
MAX_MESSAGE_BYTES = 64 * 1024
MAX_SAMPLES = 512


def _current_modality(value: object) -> object:
    # The old spelling is read as today's before the name is checked, so the store, the device
    # and every reply see one name (and a refusal lists only today's names).
    return modality_name(value) if isinstance(value, str) else value


Modality = Annotated[Literal["tactile", "auditory", "audio-tactile", "none"],
                     BeforeValidator(_current_modality)]
Ink = Literal["visible", "hidden"]
PointerType = Literal["pen", "touch", "mouse", "unknown"]
ErrorCode = Literal["binary", "too_large", "invalid_json", "invalid_message", "protocol",
                    "unknown_pen", "store", "internal"]

PAGE_PATTERN = r"^[A-Za-z0-9_-]{8,64}$"

Seq = Annotated[int, Field(ge=0, le=MAX_JSON_INT)]  # echoed in the reply, never stored
StrokeNo = Annotated[int, Field(ge=0, le=MAX_STORED_INT)]
StudyId = Annotated[int, Field(ge=1, le=MAX_STORED_INT)]


class _Message(BaseModel):
    # strict: JSON types are taken as they are — true, "3" or 1.0 is not a seq, "0.5" is not a
    # pressure, 1 is not a boolean (a number field still takes a JSON integer: 0 is 0.0).
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, strict=True)


class Hello(_Message):
    """First message of a connection."""

    type: Literal["hello"]
    seq: Seq
    client: str = Field(min_length=1, max_length=200)
    protocol: Literal[1] = PROTOCOL
    page: str | None = Field(None, pattern=PAGE_PATTERN)


Sample = StrokeSample
"""One pen sample (a coalesced pointer event): the one stroke-sample definition."""


class PenDown(_Message):
    """A stroke starts."""

    type: Literal["pen_down"]
    seq: Seq
    stroke: StrokeNo
    t: Time
    pen: str = Field(pattern=NAME_PATTERN)
    profile_version: str = Field(pattern=r"^[0-9a-f]{12}$")
    modality: Modality
    ink: Ink = "visible"
    pointer_type: PointerType = "pen"
    px_per_mm: float = Field(gt=0, le=1000)
    calibrated: bool = False
    study_session: StudyId | None = None
    trial: StudyId | None = None


class Samples(_Message):
    """A batch of samples of the open stroke."""

    type: Literal["samples"]
    seq: Seq
    stroke: StrokeNo
    samples: list[Sample] = Field(min_length=1, max_length=MAX_SAMPLES)
    index: int | None = Field(None, ge=0, le=MAX_STORED_INT)

    @model_validator(mode="after")
    def _last_number_is_stored(self) -> Samples:
        # Each sample is stored under its own number: the batch's last must fit the store too.
        if self.index is not None and self.index + len(self.samples) - 1 > MAX_STORED_INT:
            raise ValueError(f"the batch's last sample would be number "
                             f"{self.index + len(self.samples) - 1} (index {self.index} + "
                             f"{len(self.samples)} samples - 1); sample numbers go up to "
                             f"{MAX_STORED_INT}")
        return self


class Gain(_Message):
    """The open stroke's new target gain: Eq. 1 before smoothing (the device smooths)."""

    type: Literal["gain"]
    seq: Seq
    stroke: StrokeNo
    t: Time
    target: float = Field(ge=0, le=1000)


class PenUp(_Message):
    """The stroke ends."""

    type: Literal["pen_up"]
    seq: Seq
    stroke: StrokeNo
    t: Time


ClientMessage = Annotated[Hello | PenDown | Samples | Gain | PenUp,
                          Field(discriminator="type")]
CLIENT_MESSAGE: TypeAdapter = TypeAdapter(ClientMessage)


class Ack(_Message):
    """Reply to a message the server accepted."""

    type: Literal["ack"] = "ack"
    seq: int
    of: str
    server_ns: int = Field(description="time.monotonic_ns() when the message arrived")
    session: str | None = None
    stroke_id: int | None = None


class Error(_Message):
    """Reply to a message the server refused; the connection stays open."""

    type: Literal["error"] = "error"
    seq: int | None = None
    code: ErrorCode
    message: str


class MessageError(RealPenError):
    """A message that cannot be accepted; becomes an :class:`Error` reply.

    Attributes:
        code: the reply's ``code`` (:data:`ErrorCode`).
        message: what is wrong, on one line.
        seq: the refused message's ``seq``, when it could be read.
    """

    def __init__(self, code: str, message: str, seq: int | None = None):
        super().__init__(message)
        self.code, self.message, self.seq = code, message, seq

    def reply(self) -> Error:
        """The :class:`Error` reply to send."""
        return Error(seq=self.seq, code=self.code, message=self.message)


def _salvage_seq(raw: str) -> int | None:
    """The ``seq`` of a message that failed validation, when it can be read."""
    try:
        document = json.loads(raw)
    except ValueError:
        return None
    seq = document.get("seq") if isinstance(document, dict) else None
    return seq if isinstance(seq, int) and not isinstance(seq, bool) and 0 <= seq <= MAX_JSON_INT \
        else None


def parse_message(raw: str | bytes, limit: int = MAX_MESSAGE_BYTES):
    """Validate one WebSocket frame and return the message model.

    Raises:
        MessageError: a binary frame, a frame over ``limit`` bytes, invalid JSON or a schema
            violation (the message names the first offending field).
    """
    if isinstance(raw, (bytes, bytearray)):
        raise MessageError("binary", "send JSON text frames, not binary frames")
    size = len(raw) if len(raw) * 4 <= limit else len(raw.encode("utf-8", "surrogatepass"))
    if size > limit:
        raise MessageError("too_large", f"message is {size} bytes; the limit is {limit}")
    try:
        return CLIENT_MESSAGE.validate_json(raw)
    except ValidationError as error:
        problems = error.errors(include_url=False, include_input=False)
        if problems and problems[0]["type"] == "json_invalid":
            detail = problems[0].get("ctx", {}).get("error", "")
            raise MessageError("invalid_json", f"not valid JSON ({detail})") from None
        raise MessageError("invalid_message", validation_line(problems),
                           _salvage_seq(raw)) from None
