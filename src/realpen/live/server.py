"""Running the live app under uvicorn: binding, the URL to print, a clean stop on Ctrl-C.

The socket is bound before uvicorn starts, so port 0 (any free port) still prints the
real URL, and a port in use is one clear error. uvicorn handles SIGINT/SIGTERM: it stops
accepting, closes the WebSockets (each page's open stroke is ended), then the app's shutdown
closes the store, whose every stroke was committed as it was drawn.

Slow and idle clients are timed out: a request's head (request line and headers) must arrive
within :data:`REQUEST_HEAD_TIMEOUT_S`, an idle keep-alive connection is closed after
:data:`KEEP_ALIVE_S`, and at most :data:`MAX_CONNECTIONS` connections are served at once (more
get 503). WebSocket keepalive pings allow :data:`WS_PING_TIMEOUT_S` for the answer: a page
under backpressure answers late, and must not be cut off for it.
"""

from __future__ import annotations

import logging
import socket

import uvicorn
from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from realpen.errors import ParameterError
from realpen.live.auth import SecurityHeaders

WS_MAX_FRAME = 1024 * 1024  # frames above this are refused by the protocol layer (close 1009)
REQUEST_HEAD_TIMEOUT_S = 10.0
KEEP_ALIVE_S = 5
MAX_CONNECTIONS = 1000
WS_PING_INTERVAL_S = 20.0
WS_PING_TIMEOUT_S = 60.0


class TimedHttpProtocol(HttpToolsProtocol):
    """uvicorn's HTTP protocol with a deadline for each request's head.

    uvicorn times out idle keep-alive connections, but not a connection that never sends a
    request, or sends half of one's headers and stops (each would hold a connection forever).
    """

    _head_deadline = None
    head_timeout_s = REQUEST_HEAD_TIMEOUT_S

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
        self._arm_head_deadline()

    def on_message_begin(self) -> None:
        super().on_message_begin()
        self._arm_head_deadline()

    def on_headers_complete(self) -> None:
        self._disarm_head_deadline()
        super().on_headers_complete()

    def connection_lost(self, exc) -> None:
        self._disarm_head_deadline()
        super().connection_lost(exc)


class OneLineFrameErrors(logging.Filter):
    """Logs a WebSocket text frame that is not UTF-8 as one line (uvicorn logs a traceback)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.getMessage().startswith("Invalid UTF-8"):
            record.msg, record.args = ("WebSocket: a text frame that is not valid UTF-8 was "
                                       "refused (connection closed with 1007)"), ()
            record.exc_info = record.exc_text = None
            record.levelno, record.levelname = logging.WARNING, "WARNING"
        return True


ONE_LINE_FRAME_ERRORS = OneLineFrameErrors()  # one instance: adding it twice is a no-op


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port`` (``port`` 0: any free port).

    Raises:
        ParameterError: ``port`` is not 0–65535, or cannot be listened on (in use, no
            permission, or ``host`` is not this machine's).
    """
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise ParameterError("port", f"{port!r} is not a port number (0–65535)")
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if family == socket.AF_INET6 and host == "::":
            sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 0)
        sock.bind((host, port))
        sock.listen(128)
    except OSError as error:
        sock.close()
        raise ParameterError("port", f"cannot listen on {host} port {port} "
                                     f"({error.strerror or error})") from None
    return sock


def lan_address() -> str:
    """This machine's address on its network (what a tablet on the same network can reach)."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect(("192.0.2.1", 9))  # TEST-NET-1: routing decides, no packet is sent
            address = probe.getsockname()[0]
            if not address.startswith("0."):
                return address
    except OSError:
        pass
    try:
        return socket.gethostbyname(socket.gethostname())
    except OSError:
        return "127.0.0.1"


def url_host(host: str) -> str:
    """``host`` as it goes into a URL (IPv6 in brackets)."""
    return f"[{host}]" if ":" in host else host


def server_config(app, log_level: str = "warning",
                  head_timeout_s: float = REQUEST_HEAD_TIMEOUT_S) -> uvicorn.Config:
    """The uvicorn configuration of the live server (timeouts and limits above).

    The access log is off: in LAN mode every request line would carry the token.
    """
    http = type("TimedHttpProtocol", (TimedHttpProtocol,), {"head_timeout_s": head_timeout_s})
    # Outside the app as well: the 500 page of an unexpected error (made by Starlette's
    # outermost middleware) gets the headers too. Headers already set are not repeated.
    config = uvicorn.Config(SecurityHeaders(app), log_level=log_level, access_log=False, lifespan="on",
                            http=http, ws_max_size=WS_MAX_FRAME, ws_per_message_deflate=False,
                            ws_ping_interval=WS_PING_INTERVAL_S, ws_ping_timeout=WS_PING_TIMEOUT_S,
                            timeout_keep_alive=KEEP_ALIVE_S, limit_concurrency=MAX_CONNECTIONS,
                            timeout_graceful_shutdown=5)
    # After Config: it configures uvicorn's loggers.
    logging.getLogger("uvicorn.error").addFilter(ONE_LINE_FRAME_ERRORS)
    return config


def run(app, sock: socket.socket, log_level: str = "warning") -> None:
    """Serve ``app`` on ``sock`` until SIGINT/SIGTERM; returns after a graceful shutdown."""
    uvicorn.Server(server_config(app, log_level)).run(sockets=[sock])
