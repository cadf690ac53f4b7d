"""Where RealPen keeps the user's things: profiles and the stroke store."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["data_dir", "user_profiles_dir", "default_store"]


def data_dir() -> Path:
    """The user's RealPen data folder.

    ``$REALPEN_HOME`` if set; else ``$XDG_DATA_HOME/realpen``; else ``~/.local/share/realpen``
    (``%APPDATA%\\realpen`` on Windows). Not created here.
    """
    if os.environ.get("REALPEN_HOME"):
        return Path(os.environ["REALPEN_HOME"]).expanduser()
    if os.name == "nt" and os.environ.get("APPDATA"):
        return Path(os.environ["APPDATA"]) / "realpen"
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "realpen"


def user_profiles_dir() -> Path:
    """Folder of the user's own pen profiles (``profile build -o`` anywhere also works)."""
    return data_dir() / "profiles"


def default_store() -> Path:
    """The embedded SQLite stroke store of the live app."""
    return data_dir() / "strokes.sqlite3"
