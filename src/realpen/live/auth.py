"""Who may talk to the live server: the LAN token, the Host and the Origin.

With a token (LAN mode makes a random one), every HTTP request and WebSocket handshake must
carry it: as ``?token=…`` (the URL the server prints), as the ``realpen_token`` cookie (set on
the first request that carried it, so the page's module imports and fetches need nothing more),
or as ``Authorization: Bearer …``. Without it, HTTP gets 401 and a WebSocket handshake 403.

Two further checks close the holes a server on 127.0.0.1 would otherwise have against web
pages on other sites: a WebSocket handshake whose ``Origin`` is not the server's own is refused
(403), and with ``allowed_hosts`` (the loopback names, by default) a request whose ``Host`` is
another name is refused (400), which defeats DNS rebinding.
"""

from __future__ import annotations

import secrets
from collections.abc import Collection
from urllib.parse import parse_qs, urlsplit

from starlette.datastructures import Headers
from starlette.responses import PlainTextResponse

COOKIE = "realpen_token"
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")


def new_token() -> str:
    """A random URL-safe token (128 bits)."""
    return secrets.token_urlsafe(16)


def _hostname(host_header: str) -> str:
    return (urlsplit(f"//{host_header}").hostname or "").lower()


class AccessGuard:
    """ASGI middleware enforcing the token, the Host and the WebSocket Origin."""

    def __init__(self, app, token: str | None = None,
                 allowed_hosts: Collection[str] | None = None):
        self.app = app
        self.token = token
        self.allowed_hosts = {h.lower() for h in allowed_hosts} if allowed_hosts else None

    def _refusal(self, scope, headers: Headers) -> tuple[int, str] | None:
        host = headers.get("host", "")
        if self.allowed_hosts is not None and _hostname(host) not in self.allowed_hosts:
            return 400, "invalid Host header"
        origin = headers.get("origin")
        if scope["type"] == "websocket" and origin and urlsplit(origin).netloc.lower() != \
                host.lower():
            return 403, "cross-origin WebSocket refused"
        if self.token is None:
            return None
        query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
        offered = query.get("token", [None])[0]
        if offered is None:
            authorization = headers.get("authorization", "")
            if authorization.lower().startswith("bearer "):
                offered = authorization[7:].strip()
        if offered is None:
            offered = _cookie(headers.get("cookie", ""), COOKIE)
        if offered is None:
            return 401, "this server needs its token: open the URL it printed (…/?token=…)"
        if not secrets.compare_digest(offered.encode(), self.token.encode()):
            return 401, "wrong token: open the URL the server printed"
        return None

    async def __call__(self, scope, receive, send):
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = Headers(scope=scope)
        refusal = self._refusal(scope, headers)
        if refusal is not None:
            status, text = refusal
            if scope["type"] == "http":
                await PlainTextResponse(text, status_code=status)(scope, receive, send)
            else:  # closing before accepting: the server answers the handshake with 403
                await send({"type": "websocket.close", "code": 1008, "reason": text})
            return
        if self.token is None or scope["type"] != "http" or b"token=" not in \
                scope.get("query_string", b""):
            await self.app(scope, receive, send)
            return
        cookie = (f"{COOKIE}={self.token}; Path=/; HttpOnly; SameSite=Strict").encode()

        async def send_with_cookie(message):
            if message["type"] == "http.response.start":
                message = {**message, "headers": [*message.get("headers", []),
                                                  (b"set-cookie", cookie)]}
            await send(message)

        await self.app(scope, receive, send_with_cookie)


def _cookie(header: str, name: str) -> str | None:
    for part in header.split(";"):
        key, _, value = part.strip().partition("=")
        if key == name:
            return value
    return None
