"""What one page's WebSocket messages do: validate, drive the device, store, reply.

One :class:`Session` per connection. A page has at most one stroke down at a time; a new
``pen_down`` while one is down ends it first (reason ``replaced``), and a connection that
closes with a stroke down ends it (``disconnect``), so the device always hears a ``pen_up`` for
every ``pen_down`` and no stroke is left open in the store.

A page that reconnects says who it is (``hello.page``) and sends again what was not
acknowledged: its strokes are found in the store by page and stroke number, and samples and
pen-ups for a stroke the server had ended for it (``disconnect``, ``crash``) are taken, each
sample once. The reply to a message is sent only after the store has committed it, so an ack
means the data is on disk.

The device is told first and the store second, so the pen's actuator never waits for the disk.
Nothing a page sends can raise out of :meth:`Session.handle`: every problem becomes an
``error`` reply and the connection stays open.
"""

from __future__ import annotations

import asyncio
import logging
import time
import uuid
from dataclasses import dataclass

from realpen.defaults import modality_name
from realpen.errors import ParameterError
from realpen.live.catalog import Catalog
from realpen.live.device import Origin, PenDevice
from realpen.live.messages import (
    MAX_MESSAGE_BYTES,
    Ack,
    Error,
    Gain,
    Hello,
    MessageError,
    PenDown,
    PenUp,
    Samples,
    parse_message,
)
from realpen.live.store import StrokeStore
from realpen.study.db import STORE_ERRORS, error_line

__all__ = ["Session", "OpenStroke", "TACTILE_MODALITIES"]

log = logging.getLogger(__name__)
TACTILE_MODALITIES = ("tactile", "audio-tactile")


@dataclass
class OpenStroke:
    """The stroke a page has down."""

    number: int
    stroke_id: int
    a_max: float
    tactile: bool


class Session:
    """The server side of one page connection."""

    def __init__(self, catalog: Catalog, store: StrokeStore, device: PenDevice,
                 max_message_bytes: int = MAX_MESSAGE_BYTES,
                 pages: dict[str, Session] | None = None):
        self.id = uuid.uuid4().hex[:12]
        self.page = self.id  # until the page's hello names it
        # The live session of each page (shared by the server's sessions): when a page comes
        # back on a new connection while its old one is not yet known to be dead, the new one
        # takes over and the old one, closing later, leaves the pen and the store alone.
        self.pages = pages if pages is not None else {}
        self.catalog, self.store, self.device = catalog, store, device
        self.max_message_bytes = max_message_bytes
        self.stroke: OpenStroke | None = None
        self.received = self.refused = 0
        self.known_trials: set[tuple[int, int]] = set()

    async def handle(self, raw: str | bytes) -> Ack | Error:
        """Handle one frame and return the reply to send (after the store committed it)."""
        arrived = time.monotonic_ns()
        self.received += 1
        message = None
        try:
            message = parse_message(raw, self.max_message_bytes)
            extra = await self._dispatch(message)
            return Ack(seq=message.seq, of=message.type, server_ns=arrived, **extra)
        except MessageError as error:
            self.refused += 1
            if error.seq is None and message is not None:
                error.seq = message.seq
            return error.reply()
        except ParameterError as error:  # a number no store can hold (the store's own check)
            self.refused += 1
            return Error(seq=getattr(message, "seq", None), code="invalid_message",
                         message=str(error))
        except STORE_ERRORS as error:
            self.refused += 1
            log.error("stroke store: %s", error_line(error))
            return Error(seq=getattr(message, "seq", None), code="store",
                         message=f"the stroke store could not record it ({error_line(error)}); "
                                 f"send it again")
        except Exception:  # a bug must not take the connection or the server down
            self.refused += 1
            log.exception("session %s: unexpected error", self.id)
            return Error(seq=getattr(message, "seq", None), code="internal",
                         message="internal error (logged on the server)")

    async def _check_trial(self, study_session: int, trial: int) -> None:
        """Refuse a stroke for a study trial that does not exist (checked once per trial)."""
        if (study_session, trial) in self.known_trials:
            return
        from realpen.study.sessions import trial_exists

        if not await asyncio.wrap_future(self.store.read(trial_exists, study_session, trial)):
            raise MessageError("invalid_message", f"pen_down: study session {study_session} has "
                                                  f"no trial {trial}")
        self.known_trials.add((study_session, trial))

    async def _dispatch(self, message) -> dict:
        if isinstance(message, Samples):
            stroke_id = await self._stroke_id(message.stroke)
            await asyncio.wrap_future(self.store.append(stroke_id, message.samples,
                                                        message.index))
            return {}
        if isinstance(message, Gain):
            if self.stroke is None or self.stroke.number != message.stroke:
                await self._stroke_id(message.stroke)  # resent after a reconnect
            stroke = self.stroke
            if stroke is None or stroke.number != message.stroke:
                return {}  # a gain of an earlier stroke: the pen has moved on
            if message.target > stroke.a_max * (1 + 1e-9):
                raise MessageError("invalid_message", f"gain.target: {message.target:g} is above "
                                   f"the pen's a_max {stroke.a_max:g}")
            if stroke.tactile:
                self.device.gain(Origin(self.id, message.stroke, message.seq), message.target)
            return {}
        if isinstance(message, PenDown):
            return await self._pen_down(message)
        if isinstance(message, PenUp):
            stroke_id = await self._stroke_id(message.stroke)
            if self.stroke is not None and self.stroke.number == message.stroke:
                await self._end("pen_up", message.seq)
            else:  # the pen-up of a stroke already ended (resent after a reconnect)
                await asyncio.wrap_future(self.store.end(stroke_id, "pen_up"))
            return {}
        if isinstance(message, Hello):
            if message.page is not None and message.page != self.page:
                self._release_page()
                self.page = message.page
                older = self.pages.get(self.page)
                if older is not None and older is not self:
                    older.detach()
                self.pages[self.page] = self
            return {"session": self.id}
        raise MessageError("invalid_message", f"unhandled message type {message.type}")

    async def _pen_down(self, message: PenDown) -> dict:
        entry = self.catalog.get(message.pen)
        if entry is None:
            raise MessageError("unknown_pen", f"pen_down.pen: no profile '{message.pen}' on this "
                               f"server (known: {', '.join(self.catalog.names)})")
        profile = entry.profile
        if message.profile_version != profile.version:
            raise MessageError("unknown_pen", f"pen_down.profile_version: the page has "
                               f"'{message.pen}' version {message.profile_version}, the server "
                               f"{profile.version}; reload the page")
        if (message.study_session is None) != (message.trial is None):
            raise MessageError("invalid_message", "pen_down: give both study_session and trial, "
                                                  "or neither")
        if message.study_session is not None:
            await self._check_trial(message.study_session, message.trial)
        if self.stroke is not None:
            await self._end("replaced", message.seq)
        tactile = message.modality in TACTILE_MODALITIES
        origin = Origin(self.id, message.stroke, message.seq)
        self.device.pen_down(origin, profile, tactile)
        begun = self.store.begin(
            session=self.id, page=self.page, page_stroke=message.stroke, pen=profile.name,
            profile_version=profile.version, modality=message.modality, ink=message.ink,
            pointer_type=message.pointer_type, px_per_mm=message.px_per_mm,
            calibrated=message.calibrated, page_t0=message.t,
            study_session=message.study_session, trial=message.trial)
        try:
            stroke_id = await asyncio.wrap_future(begun)
        except BaseException:  # not recorded: the pen is lifted, the page will send it again
            self.device.pen_up(origin)
            raise
        self.stroke = OpenStroke(message.stroke, stroke_id, profile.meta.coupling.a_max, tactile)
        return {"stroke_id": stroke_id}

    async def _stroke_id(self, number: int) -> int:
        """The store id of this page's stroke ``number``: the one down, or one the page drew
        before (resent messages after a reconnect). A stroke the server ended for the page
        (a disconnect, a crash) is taken up again: the pen goes down on the device, so the rest
        of the stroke is felt.

        Raises:
            MessageError: the page never put that stroke down.
        """
        if self.stroke is not None and self.stroke.number == number:
            return self.stroke.stroke_id
        found = await asyncio.wrap_future(self.store.find(self.page, number))
        if found is None:
            down = "no stroke is down" if self.stroke is None else \
                f"stroke {self.stroke.number} is down"
            raise MessageError("protocol", f"stroke {number} is not down ({down})")
        entry = self.catalog.get(found.pen)
        if self.stroke is None and found.end_reason != "pen_up" and entry is not None:
            # a stroke stored by an earlier release may say "auditory-tactile"
            tactile = modality_name(found.modality) in TACTILE_MODALITIES
            self.device.pen_down(Origin(self.id, number, None), entry.profile, tactile)
            self.stroke = OpenStroke(number, found.stroke_id,
                                     entry.profile.meta.coupling.a_max, tactile)
        return found.stroke_id

    async def _end(self, reason: str, seq: int | None = None) -> None:
        stroke, self.stroke = self.stroke, None
        if stroke is None:
            return
        self.device.pen_up(Origin(self.id, stroke.number, seq))
        await asyncio.wrap_future(self.store.end(stroke.stroke_id, reason))

    def detach(self) -> None:
        """The page has come back on another connection, which now owns its stroke: this
        one, closing later, must neither lift the pen nor end the stroke."""
        self.stroke = None
        self._release_page()

    def _release_page(self) -> None:
        if self.pages.get(self.page) is self:
            del self.pages[self.page]

    async def close(self) -> None:
        """The connection closed: end a stroke left down (reason ``disconnect``)."""
        self._release_page()
        try:
            await self._end("disconnect")
        except Exception:
            log.exception("session %s: closing", self.id)

    def close_now(self) -> None:
        """:meth:`close` from outside the event loop (the server's shutdown): the store's
        ``shutdown`` pass ends the stroke, the device hears its pen-up here."""
        stroke, self.stroke = self.stroke, None
        if stroke is not None:
            self.device.pen_up(Origin(self.id, stroke.number, None))
