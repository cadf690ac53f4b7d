"""A minimal client of the live server's WebSocket that loses nothing (docs/live.md, "Clients").

It follows the server's rule: send as fast as you like, read the replies as they come, keep
every message until its ``ack``, and after a lost connection or an ``error`` of code ``store``
connect again, name the same page in ``hello`` and send again, in order, what was not
acknowledged. The server stores a message once however often it is sent.

Run it against a server (``realpen serve``, then in another terminal)::

    python docs/examples/live_client.py ws://127.0.0.1:8000/ws

It draws one stroke of 2,000 samples with the bundled pencil and prints what was acknowledged.
A PsychoPy or jsPsych bridge can take :func:`send_reliably` as it is.
"""

from __future__ import annotations

import asyncio
import json
import sys
import uuid

from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed


async def send_reliably(url: str, messages: list[dict], page: str | None = None) -> int:
    """Send ``messages`` (dicts without ``seq``) over the live WebSocket at ``url`` until the
    server has acknowledged every one; returns how many connections it took.

    Raises:
        RuntimeError: the server refused a message as invalid (a bug of the caller: the
            message would be refused again).
    """
    page = page or f"client-{uuid.uuid4().hex[:12]}"
    frames = {seq: json.dumps({**message, "seq": seq})
              for seq, message in enumerate(messages, start=1)}
    unacknowledged = dict(frames)  # seq -> frame, in sending order
    connections = 0
    while unacknowledged:
        connections += 1
        try:
            # ping_interval=None: under backpressure the library's own ping would wait behind
            # our messages, and the library would close the connection for it.
            async with connect(url, open_timeout=60, ping_interval=None) as ws:
                await ws.send(json.dumps({"type": "hello", "seq": 0, "client": "example",
                                          "page": page}))

                async def read_replies():
                    async for text in ws:
                        reply = json.loads(text)
                        if reply["type"] == "ack":
                            unacknowledged.pop(reply["seq"], None)
                            if not unacknowledged:
                                return
                        elif reply.get("code") == "store":  # the server closes; we resend
                            continue
                        else:
                            raise RuntimeError(f"refused: {reply['message']}")

                reader = asyncio.create_task(read_replies())
                try:
                    for frame in list(unacknowledged.values()):  # in order, all at once
                        await ws.send(frame)  # waits when the server is behind: backpressure
                finally:
                    await asyncio.gather(reader, return_exceptions=True)
                if reader.exception() is not None:
                    raise reader.exception()
        except (ConnectionClosed, OSError):
            await asyncio.sleep(min(5.0, 0.2 * connections))  # then send again what is left
    return connections


def one_stroke(pen: str, profile_version: str, samples: int = 2000) -> list[dict]:
    """A straight stroke of ``samples`` samples at 250 Hz, in batches of 8."""
    messages = [{"type": "pen_down", "stroke": 1, "t": 0.0, "pen": pen,
                 "profile_version": profile_version, "modality": "tactile",
                 "px_per_mm": 4.0}]
    for first in range(0, samples, 8):
        batch = [{"t": k / 250, "x": k * 0.2, "y": 10.0, "pressure": 0.5, "speed": 50.0}
                 for k in range(first, min(first + 8, samples))]
        messages.append({"type": "samples", "stroke": 1, "index": first, "samples": batch})
    messages.append({"type": "pen_up", "stroke": 1, "t": samples / 250})
    return messages


if __name__ == "__main__":
    import urllib.request

    server = sys.argv[1] if len(sys.argv) > 1 else "ws://127.0.0.1:8000/ws"
    base = server.replace("ws://", "http://").rsplit("/ws", 1)[0]
    with urllib.request.urlopen(f"{base}/api/profiles") as answer:
        pencil = next(p for p in json.load(answer)["profiles"] if p["name"] == "pencil")
    stroke = one_stroke("pencil", pencil["version"])
    taken = asyncio.run(send_reliably(server, stroke))
    print(f"{len(stroke)} messages acknowledged (stored) over {taken} connection(s)")
