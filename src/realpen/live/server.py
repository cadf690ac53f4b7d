"""Running the live app under uvicorn: binding, the URL to print, a clean stop on Ctrl-C.

The socket is bound before uvicorn starts, so port 0 (any free port) still prints the
real URL, and a port in use is one clear error. uvicorn handles SIGINT/SIGTERM: it stops
accepting, closes the WebSockets (each page's open stroke is ended), then the app's shutdown
closes the store, whose every stroke was committed as it was drawn.
"""

from __future__ import annotations

import socket

import uvicorn

from realpen.errors import ParameterError

WS_MAX_FRAME = 1024 * 1024  # frames above this are refused by the protocol layer (close 1009)


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


def run(app, sock: socket.socket, log_level: str = "warning") -> None:
    """Serve ``app`` on ``sock`` until SIGINT/SIGTERM; returns after a graceful shutdown.

    The access log is off: in LAN mode every request line would carry the token.
    """
    config = uvicorn.Config(app, log_level=log_level, access_log=False, lifespan="on",
                            ws_max_size=WS_MAX_FRAME, ws_per_message_deflate=False,
                            timeout_graceful_shutdown=5)
    uvicorn.Server(config).run(sockets=[sock])
