"""The live server's HTTP and WebSocket protocols: uvicorn's, with bounds and a fair liveness rule.

**HTTP** (:class:`GuardedHttpProtocol`). A request's head (request line and headers) must
arrive within ``head_timeout_s`` and hold at most :data:`MAX_HEAD_BYTES` bytes and
:data:`MAX_HEADERS` header lines; a larger one is answered 431 and the connection closed as soon
as the limit is passed, so a 128 MB header costs the server 64 KiB and no other page waits for
it. The token is checked once the head is complete, before any body is read
(:class:`~realpen.live.bodies.BodyLimit`). The answers the protocol makes itself — 400 for a
request that is not HTTP, 431, and 503 above :data:`MAX_CONNECTIONS` connections (WebSockets
included) — carry the
same security headers as every answer of the app (uvicorn's own carry none).

**WebSocket** (:class:`PatientWebSocketProtocol`). The server pings every
:data:`WS_PING_INTERVAL_S` and counts a client's silence (nothing at all heard from it: a
frame, a pong, a byte) only while it waits on that client. While the server holds a message of
the client it has not yet stored (the client is ahead and waits in its TCP window: that is the
backpressure), or waits for the client to read its replies, the client's pong is queued behind
data and cannot arrive, and no time is counted, however long the store takes.

A connection that has sent no message is closed after :data:`WS_PING_TIMEOUT_S` of silence,
so a socket that stalls after its handshake is released within ``WS_PING_INTERVAL_S +
WS_PING_TIMEOUT_S`` (8 s). A client that has sent messages is allowed
:data:`WS_SPOKEN_SILENCE_S`: on a loaded machine a client's process can go seconds without
being scheduled, and cutting it would lose what it had not yet sent. A client that takes none
of its replies (does not read) for :data:`WS_SPOKEN_SILENCE_S` is closed too. Before closing,
the server looks once more for what the client sent (:data:`CONFIRM_S`), because an event loop
that runs its timers before it polls the sockets (uvloop) would otherwise judge a client silent
after a busy spell of its own.
"""

from __future__ import annotations

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol
from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

from realpen.live.auth import CONTENT_SECURITY_POLICY, SECURITY_HEADERS

__all__ = ["GuardedHttpProtocol", "PatientWebSocketProtocol", "plain_answer",
           "MAX_HEAD_BYTES", "MAX_HEADERS", "MAX_CONNECTIONS", "REQUEST_HEAD_TIMEOUT_S",
           "WS_PING_INTERVAL_S", "WS_PING_TIMEOUT_S", "WS_SPOKEN_SILENCE_S"]

MAX_HEAD_BYTES = 64 * 1024  # browsers send a few kB; 64 KiB leaves room for large cookies
MAX_HEADERS = 100
MAX_CONNECTIONS = 1000
REQUEST_HEAD_TIMEOUT_S = 10.0
WS_PING_INTERVAL_S = 3.0
WS_PING_TIMEOUT_S = 5.0
WS_SPOKEN_SILENCE_S = 60.0
CONFIRM_S = 0.25  # a last look for the client's bytes before a connection is closed
LINGER_S = 2.0  # how long a refused request's remaining bytes are read and dropped
_STATUS_TEXT = {400: "Bad Request", 431: "Request Header Fields Too Large",
                503: "Service Unavailable"}
_HEAD_END = b"\r\n\r\n"


def plain_answer(status: int, text: str) -> bytes:
    """A whole HTTP/1.1 answer: ``status``, the security headers, ``text`` as a one-line
    plain-text body, and ``connection: close``."""
    body = f"{text}\n".encode()
    lines = [f"HTTP/1.1 {status} {_STATUS_TEXT.get(status, '')}".encode(),
             b"content-type: text/plain; charset=utf-8",
             b"content-length: " + str(len(body)).encode(),
             b"connection: close",
             b"content-security-policy: " + CONTENT_SECURITY_POLICY.encode(),
             *(name + b": " + value for name, value in SECURITY_HEADERS)]
    return b"\r\n".join(lines) + b"\r\n\r\n" + body


class _Refused(Exception):
    """Raised from a parser callback to stop parsing a request the server refuses."""


class GuardedHttpProtocol(HttpToolsProtocol):
    """uvicorn's HTTP protocol with a deadline, a size and a header count for each request's
    head, and its own answers (400, 431, 503) carrying the security headers."""

    head_timeout_s = REQUEST_HEAD_TIMEOUT_S
    max_head_bytes = MAX_HEAD_BYTES
    max_headers = MAX_HEADERS
    max_connections = MAX_CONNECTIONS
    _head_deadline = None
    _refusal: tuple[int, str] | None = None
    _discarding = False

    # ---- the head's deadline: uvicorn times out idle keep-alive connections, but not one that
    # never sends a request, or sends half of one's headers and stops.
    def _arm_head_deadline(self) -> None:
        self._disarm_head_deadline()
        self._head_deadline = self.loop.call_later(self.head_timeout_s, self._head_timeout)

    def _disarm_head_deadline(self) -> None:
        if self._head_deadline is not None:
            self._head_deadline.cancel()
            self._head_deadline = None

    def _head_timeout(self) -> None:
        self._head_deadline = None
        if not self.transport.is_closing():
            self.transport.close()

    def connection_made(self, transport) -> None:
        super().connection_made(transport)
        self._in_head, self._head_bytes, self._head_tail, self._header_count = True, 0, b"", 0
        self._arm_head_deadline()

    def connection_lost(self, exc) -> None:
        self._disarm_head_deadline()
        super().connection_lost(exc)

    # ---- the head's size, counted before the parser buffers it
    def data_received(self, data: bytes) -> None:
        if self._discarding:
            return
        past_head = None  # where in ``data`` the head being counted ends, if it does
        if self._in_head and not self.transport.is_closing():
            if self._head_deadline is None:
                # Bytes after a finished request (a stray CRLF) cancel uvicorn's keep-alive
                # timer without starting a message: the head's own deadline takes over.
                self._arm_head_deadline()
            window = self._head_tail + data
            end = window.find(_HEAD_END)
            if end >= 0:
                past_head = max(0, end + len(_HEAD_END) - len(self._head_tail))
            self._head_bytes += len(data) if past_head is None else past_head
            self._head_tail = window[-(len(_HEAD_END) - 1):]
            if self._head_bytes > self.max_head_bytes:
                self._refuse(431, f"the request's head is larger than {self.max_head_bytes:,} "
                                  f"bytes")
                return
        super().data_received(data)
        if past_head is not None and self._in_head:
            # A next request began in the same read (pipelining): its bytes so far count.
            self._head_bytes = len(data) - past_head

    def on_message_begin(self) -> None:
        super().on_message_begin()
        self._arm_head_deadline()

    def on_header(self, name: bytes, value: bytes) -> None:
        self._header_count += 1
        if self._header_count > self.max_headers:
            self._refusal = (431, f"the request has more than {self.max_headers} header lines")
            raise _Refused
        super().on_header(name, value)

    def on_headers_complete(self) -> None:
        self._disarm_head_deadline()
        self._in_head = False
        if len(self.connections) > self.max_connections or \
                len(self.tasks) >= self.max_connections:  # WebSocket upgrades included
            self._refusal = (503, "the server is serving as many connections as it can; "
                                  "try again in a moment")
            raise _Refused
        super().on_headers_complete()

    def on_message_complete(self) -> None:
        super().on_message_complete()
        self._in_head, self._head_bytes, self._head_tail, self._header_count = True, 0, b"", 0

    # ---- the protocol's own answers
    def send_400_response(self, msg: str) -> None:
        status, text = self._refusal or (400, "the request is not valid HTTP/1.1")
        self._refuse(status, text)

    def _refuse(self, status: int, text: str) -> None:
        """Answer ``status`` and close. The client may still be sending (the rest of a huge
        head): what it sends is read and dropped for :data:`LINGER_S`, because closing a socket
        with unread data resets the connection, and the reset can destroy the answer before
        the client reads it."""
        self._disarm_head_deadline()
        self._in_head, self._discarding = False, True
        if self.cycle is not None and not self.cycle.response_complete:
            # An earlier request's answer is still to come: it is sent, then the connection
            # closes; this request gets no answer of its own (it cannot be answered first).
            self.cycle.keep_alive = False
            return
        self.transport.write(plain_answer(status, text))
        if self.transport.can_write_eof():
            self.transport.write_eof()
        self.loop.call_later(LINGER_S, self.transport.close)


class PatientWebSocketProtocol(WebSocketsSansIOProtocol):
    """uvicorn's WebSocket protocol whose keepalive closes a connection for its client's
    silence only while the server waits on that client (see the module's description)."""

    spoken_silence_s = WS_SPOKEN_SILENCE_S
    _heard_at = 0.0
    _write_blocked = False
    _spoken = False
    _confirming = False
    _progress_at = 0.0
    _buffered = 0

    def connection_made(self, transport) -> None:
        super().connection_made(transport)
        self._heard_at = self.loop.time()

    def data_received(self, data: bytes) -> None:
        self._heard_at = self.loop.time()
        super().data_received(data)

    def start_keepalive(self) -> None:
        # Called when the handshake's answer is sent: silence counts from there, not from the
        # connection (a loaded server may answer a handshake seconds after it arrived).
        self._heard_at = self.loop.time()
        super().start_keepalive()

    def send_receive_event_to_app(self) -> None:
        self._spoken = True
        super().send_receive_event_to_app()

    def handle_parser_exception(self) -> None:
        if self.conn.close_sent is None:
            # Frames before the handshake's answer (a client that does not wait for 101): the
            # parser fails without a close frame to send, and uvicorn would log a traceback.
            self.queue.put_nowait({"type": "websocket.disconnect", "code": 1002})
            self.close_sent = True
            self.transport.close()
            return
        super().handle_parser_exception()

    def pause_writing(self) -> None:
        self._write_blocked = True
        self._progress_at = self.loop.time()
        self._buffered = self.transport.get_write_buffer_size()
        super().pause_writing()

    def resume_writing(self) -> None:
        self._write_blocked = False
        super().resume_writing()

    def _writes_progressed(self) -> bool:
        """While the client does not read, whether it has taken any reply lately."""
        buffered = self.transport.get_write_buffer_size()
        if buffered < self._buffered:
            self._progress_at = self.loop.time()
        self._buffered = buffered
        return self.loop.time() - self._progress_at < self.spoken_silence_s

    def keepalive_timeout(self) -> None:
        if self.read_paused and not self._write_blocked:
            # The server holds a message of the client it has not yet stored: the client's
            # pong is queued behind its own messages.
            wait = self.ping_timeout
        elif self._write_blocked:  # the pong is behind the replies the client has not read
            wait = self.ping_timeout if self._writes_progressed() else 0.0
        else:
            allowed = self.spoken_silence_s if self._spoken else self.ping_timeout
            wait = self._heard_at + allowed - self.loop.time()
        if wait <= 0 and not self._confirming:
            # One more turn of the event loop first: an event loop that runs its timers before
            # polling the sockets (uvloop) fires this after a busy spell before reading what
            # the client sent meanwhile.
            self._confirming, wait = True, CONFIRM_S
        elif wait > 0:
            self._confirming = False
        if wait > 0 and not self.transport.is_closing():
            self.pong_timer = self.loop.call_later(wait, self.keepalive_timeout)
            return
        super().keepalive_timeout()
        if self._write_blocked:
            self.transport.abort()  # close() would wait for the unread replies to drain
