"""Running the live app under uvicorn: binding, the URL to print, a clean stop on Ctrl-C.

The socket is bound before uvicorn starts, so port 0 (any free port) still prints the
real URL, and a port in use is one clear error. uvicorn handles SIGINT/SIGTERM: it stops
accepting, closes the WebSockets (each page's open stroke is ended), then the app's shutdown
closes the store, whose every stroke was committed as it was drawn.

Slow and idle clients are timed out, and request heads bounded, by the server's own protocols
(:mod:`realpen.live.protocols`): a request's head must arrive within
:data:`~realpen.live.protocols.REQUEST_HEAD_TIMEOUT_S` and hold at most 64 KiB and 100 header
lines, an idle keep-alive connection is closed after :data:`KEEP_ALIVE_S`, at most
:data:`~realpen.live.protocols.MAX_CONNECTIONS` connections are served at once (more get 503),
and a WebSocket is closed for silence only while the server waits on its client, never while
the client waits for the store (backpressure).
"""

from __future__ import annotations

import logging
import socket

import uvicorn

from realpen.errors import ParameterError
from realpen.live.auth import SecurityHeaders
from realpen.live.protocols import (
    MAX_CONNECTIONS,
    REQUEST_HEAD_TIMEOUT_S,
    WS_PING_INTERVAL_S,
    WS_PING_TIMEOUT_S,
    WS_SPOKEN_SILENCE_S,
    GuardedHttpProtocol,
    PatientWebSocketProtocol,
)

__all__ = ["bind", "lan_address", "url_host", "server_config", "run", "WS_MAX_FRAME",
           "KEEP_ALIVE_S"]

WS_MAX_FRAME = 1024 * 1024  # frames above this are refused by the protocol layer (close 1009)
KEEP_ALIVE_S = 5


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
                  head_timeout_s: float = REQUEST_HEAD_TIMEOUT_S,
                  max_connections: int = MAX_CONNECTIONS,
                  ws_ping_interval_s: float = WS_PING_INTERVAL_S,
                  ws_ping_timeout_s: float = WS_PING_TIMEOUT_S,
                  ws_spoken_silence_s: float = WS_SPOKEN_SILENCE_S) -> uvicorn.Config:
    """The uvicorn configuration of the live server (timeouts and limits above; the keyword
    arguments, in seconds and connections, exist for tests that cannot wait the real ones).

    The access log is off: in LAN mode every request line would carry the token.
    """
    http = type("GuardedHttpProtocol", (GuardedHttpProtocol,),
                {"head_timeout_s": head_timeout_s, "max_connections": max_connections})
    ws = type("PatientWebSocketProtocol", (PatientWebSocketProtocol,),
              {"spoken_silence_s": ws_spoken_silence_s})
    # Outside the app as well: the 500 page of an unexpected error (made by Starlette's
    # outermost middleware) gets the headers too. Headers already set are not repeated.
    config = uvicorn.Config(SecurityHeaders(app), log_level=log_level, access_log=False,
                            lifespan="on", http=http, ws=ws,
                            ws_max_size=WS_MAX_FRAME,
                            ws_per_message_deflate=False, ws_ping_interval=ws_ping_interval_s,
                            ws_ping_timeout=ws_ping_timeout_s, timeout_keep_alive=KEEP_ALIVE_S,
                            timeout_graceful_shutdown=5)
    # After Config: it configures uvicorn's loggers.
    logging.getLogger("uvicorn.error").addFilter(ONE_LINE_FRAME_ERRORS)
    return config


def run(app, sock: socket.socket, log_level: str = "warning") -> None:
    """Serve ``app`` on ``sock`` until SIGINT/SIGTERM; returns after a graceful shutdown."""
    uvicorn.Server(server_config(app, log_level)).run(sockets=[sock])
