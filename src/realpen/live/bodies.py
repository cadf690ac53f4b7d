"""Request bodies: small, and sent in time.

The study API takes JSON bodies (an answer is a few hundred bytes). :class:`BodyLimit` reads a
request's whole body before the app sees it, refusing one larger than its limit (413) or one
that does not arrive within its time (408, so a client that sends a header and then trickles
its body cannot hold a connection and its memory for ever), and gives the app the body in one
piece.
"""

from __future__ import annotations

import asyncio

from starlette.responses import JSONResponse

__all__ = ["BodyLimit", "MAX_BODY_BYTES", "BODY_TIMEOUT_S"]

MAX_BODY_BYTES = 64 * 1024
BODY_TIMEOUT_S = 10.0
_WITHOUT_BODY = ("GET", "HEAD", "OPTIONS")


class BodyLimit:
    """ASGI middleware: bodies of at most ``max_bytes``, whole within ``timeout_s`` seconds."""

    def __init__(self, app, max_bytes: int = MAX_BODY_BYTES, timeout_s: float = BODY_TIMEOUT_S):
        self.app, self.max_bytes, self.timeout_s = app, max_bytes, timeout_s

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http" or scope.get("method") in _WITHOUT_BODY:
            await self.app(scope, receive, send)
            return
        too_large = JSONResponse({"detail": f"the request body is larger than "
                                            f"{self.max_bytes:,} bytes"}, status_code=413)
        declared = dict(scope.get("headers") or ()).get(b"content-length", b"0")
        if not declared.isdigit() or int(declared) > self.max_bytes:
            await too_large(scope, receive, send)
            return
        chunks, size = [], 0
        try:
            async with asyncio.timeout(self.timeout_s):
                while True:
                    message = await receive()
                    if message["type"] == "http.disconnect":
                        return
                    chunk = message.get("body", b"")
                    size += len(chunk)
                    if size > self.max_bytes:
                        await too_large(scope, receive, send)
                        return
                    chunks.append(chunk)
                    if not message.get("more_body", False):
                        break
        except TimeoutError:
            await JSONResponse({"detail": f"the request body did not arrive within "
                                          f"{self.timeout_s:g} s"}, status_code=408)(
                scope, receive, send)
            return
        body, delivered = b"".join(chunks), False

        async def replay():
            nonlocal delivered
            if not delivered:
                delivered = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()  # after the body: only a disconnect can come

        await self.app(scope, replay, send)
