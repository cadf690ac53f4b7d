"""The pens the server offers, and their audio.

``GET /api/profiles``                        the pens offered (name, version, coupling, …)
``GET /api/profiles/{name}/sound.wav``       a pen's sound unit (32-bit float WAV)
``GET /api/profiles/{name}/tactile.wav``     a pen's tactile pattern (32-bit float WAV)
``GET /api/profiles/{name}/grid/{i}.wav``    the loop of point i of a pen's vibration grid
"""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter, HTTPException
from fastapi.responses import Response

from realpen.live.catalog import CatalogEntry
from realpen.live.routes.pages import NO_CACHE
from realpen.live.routes.params import STORED_NUMBER
from realpen.live.state import State

__all__ = ["router", "offered"]

router = APIRouter()


def offered(state: State, name: str) -> CatalogEntry:
    """The catalog entry of the pen ``name``; 404 when the server does not offer it."""
    entry = state.catalog.get(name)
    if entry is None:
        raise HTTPException(404, f"no profile '{name}'")
    return entry


@router.get("/api/profiles")
def profiles(state: State) -> dict:
    return {"profiles": state.catalog.to_json()}


@router.get("/api/profiles/{name}/{part}.wav")
def profile_audio(state: State, name: str, part: Literal["sound", "tactile"]) -> Response:
    entry = offered(state, name)
    data = entry.sound_wav if part == "sound" else entry.tactile_wav
    return Response(data, media_type="audio/wav",
                    headers={**NO_CACHE, "ETag": f'"{entry.profile.version}-{part}"'})


@router.get("/api/profiles/{name}/grid/{index}.wav")
def grid_audio(state: State, name: str, index: STORED_NUMBER) -> Response:
    entry = offered(state, name)
    try:
        data = entry.point_wav(index)
    except IndexError:
        raise HTTPException(404, f"the profile '{name}' has no grid point {index}") from None
    return Response(data, media_type="audio/wav",
                    headers={**NO_CACHE, "ETag": f'"{entry.profile.version}-grid-{index}"'})
