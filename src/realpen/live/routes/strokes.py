"""The pen events of the pages, and what the store holds.

``WS  /ws``           pen events (:mod:`realpen.live.messages`), each acknowledged once stored
``GET /api/status``   pages connected, strokes and samples stored
"""

from __future__ import annotations

from fastapi import APIRouter, WebSocket, WebSocketDisconnect

from realpen.live.state import State

__all__ = ["router"]

router = APIRouter()


@router.get("/api/status")
def status(state: State) -> dict:
    strokes, samples = state.store.count()
    return {"pages": len(state.sessions), "strokes": strokes, "samples": samples,
            "store": state.store.display}


@router.websocket("/ws")
async def pen_events(websocket: WebSocket, state: State) -> None:
    await websocket.accept()
    session = state.open_session()
    try:
        while True:
            frame = await websocket.receive()
            if frame["type"] == "websocket.disconnect":
                break
            raw = frame["text"] if frame.get("text") is not None else frame.get("bytes", b"")
            # One message at a time: the next frame is read once this one is stored and
            # acknowledged. That is the backpressure: a page that sends faster than the
            # store writes waits in its own TCP window, and no one else does.
            reply = await session.handle(raw)
            await websocket.send_text(reply.model_dump_json(exclude_none=True))
            if getattr(reply, "code", None) == "store":
                # The store could not record it: closing makes the page send again, in
                # order, everything not acknowledged (later messages depend on this one).
                await websocket.close(1011, "the stroke store could not record a message")
                break
    except (WebSocketDisconnect, OSError, RuntimeError):
        pass
    finally:
        await state.close_session(session)
