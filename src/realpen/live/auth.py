"""Who may talk to the live server: the LAN token, the Host and the Origin.

With a token (LAN mode makes a random one), every HTTP request and WebSocket handshake must
carry it: as ``?token=…`` (the URL the server prints), as the ``realpen_token`` cookie (set on
the first request that carried it, so the page's module imports and fetches need nothing more),
or as ``Authorization: Bearer …``. Without it, HTTP gets 401 and a WebSocket handshake 403.

Two further checks close the holes a server on 127.0.0.1 would otherwise have against web
pages on other sites: a WebSocket handshake whose ``Origin`` is not the server's own is refused
(403), and with ``allowed_hosts`` (the loopback names, by default) a request whose ``Host`` is
another name is refused (400), which defeats DNS rebinding.

Other sites' pages may not use the server at all: an HTTP request that the browser marks
``Sec-Fetch-Site: cross-site`` or ``same-site`` (another port of this machine is "same site"),
or whose ``Origin`` is not the server's own, is refused (403) — except following a link to the
writing page itself, which is harmless as the page may not be framed. :class:`SecurityHeaders`
adds to every response a Content-Security-Policy that allows only the server's own scripts,
styles and connections and no framing, ``X-Frame-Options: DENY``, ``nosniff`` and
``Referrer-Policy: no-referrer`` (the LAN token in a URL is never sent elsewhere).
"""

from __future__ import annotations

import os
import re
import secrets
import tempfile
from collections.abc import Collection
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

from starlette.datastructures import Headers
from starlette.responses import PlainTextResponse

from realpen.errors import fail

COOKIE = "realpen_token"
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")
CONTENT_SECURITY_POLICY = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
    "media-src 'self' blob:; connect-src 'self'; font-src 'self'; manifest-src 'self'; "
    "base-uri 'none'; form-action 'self'; frame-ancestors 'none'")
_TOKEN = re.compile(r"[A-Za-z0-9_-]{20,200}")  # what new_token makes (and a little more)
_SAFE_HOST = re.compile(r"[A-Za-z0-9.:\[\]-]{1,260}")
SECURITY_HEADERS = (
    (b"x-frame-options", b"DENY"),
    (b"x-content-type-options", b"nosniff"),
    (b"referrer-policy", b"no-referrer"),
    (b"cross-origin-opener-policy", b"same-origin"),
    (b"cross-origin-resource-policy", b"same-origin"),
)
PAGES = ("/", "/study", "/study/participant")  # what a link from elsewhere may open
ALLOWED_FETCH_SITES = ("same-origin", "none")  # "none": typed, bookmarked, opened by the user


def new_token() -> str:
    """A random URL-safe token (128 bits)."""
    return secrets.token_urlsafe(16)


def kept_token(path: Path, renew: bool = False) -> str:
    """The LAN token kept in ``path`` (readable by its owner only), made when there is none or
    ``renew``: a server started again keeps its token, so tablets that hold its URL (or its
    cookie) carry on, a study's participant screen included.

    Raises:
        RealPenError: the file cannot be read or written (one line naming it).
    """
    try:
        if not renew and path.is_file():
            token = path.read_text(encoding="ascii").strip()
            if _TOKEN.fullmatch(token):
                return token
        token = new_token()
        path.parent.mkdir(parents=True, exist_ok=True)
        # mkstemp makes the file 0600, and it keeps that mode when renamed into place.
        descriptor, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
        try:
            with os.fdopen(descriptor, "w", encoding="ascii") as handle:
                handle.write(token + "\n")
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
        return token
    except (OSError, UnicodeDecodeError) as error:
        reason = getattr(error, "strerror", None) or error
        raise fail(path, f"cannot keep the LAN token here ({reason})") from None


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
        foreign_origin = bool(origin) and urlsplit(origin).netloc.lower() != host.lower()
        if scope["type"] == "websocket" and foreign_origin:
            return 403, "cross-origin WebSocket refused"
        if scope["type"] == "http" and (foreign_origin or _cross_site(scope, headers)):
            return 403, "requests from other sites are refused"
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


def content_security_policy(host: str | None = None) -> str:
    """The page's Content-Security-Policy for a request to ``host`` (its ``Host`` header).

    ``connect-src 'self'`` covers the page's WebSocket in current browsers; Safari before 16
    does not count ``ws:`` as 'self', so the server's own ``ws://`` and ``wss://`` address is
    named as well (when the Host header is a plain host name or address).
    """
    if not host or not _SAFE_HOST.fullmatch(host):
        return CONTENT_SECURITY_POLICY
    return CONTENT_SECURITY_POLICY.replace(
        "connect-src 'self';", f"connect-src 'self' ws://{host} wss://{host};")


def _cross_site(scope, headers: Headers) -> bool:
    """A browser request made by another site's page (Fetch Metadata), other than following a
    link to one of the pages (the writing page, the study console, the participant screen)."""
    site = headers.get("sec-fetch-site")
    if site is None or site in ALLOWED_FETCH_SITES:
        return False
    navigation = headers.get("sec-fetch-mode") == "navigate" and \
        headers.get("sec-fetch-dest") == "document"
    return not (navigation and scope.get("method") == "GET" and scope.get("path") in PAGES)


class SecurityHeaders:
    """ASGI middleware adding the Content-Security-Policy (:func:`content_security_policy`)
    and :data:`SECURITY_HEADERS` to every HTTP response."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        policy = content_security_policy(Headers(scope=scope).get("host")).encode()

        async def send_with_headers(message):
            if message["type"] == "http.response.start":
                present = {name.lower() for name, _ in message.get("headers", [])}
                extra = [(name, value)
                         for name, value in ((b"content-security-policy", policy),
                                             *SECURITY_HEADERS)
                         if name not in present]
                message = {**message, "headers": [*message.get("headers", []), *extra]}
            await send(message)

        await self.app(scope, receive, send_with_headers)


def _cookie(header: str, name: str) -> str | None:
    for part in header.split(";"):
        key, _, value = part.strip().partition("=")
        if key == name:
            return value
    return None
