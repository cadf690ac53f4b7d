"""Where profiles live: the bundled pens, the user's profiles folder, and extra folders.

The user's profiles folder is :func:`realpen.io.paths.user_profiles_dir`
(``$REALPEN_HOME/profiles``, else ``$XDG_DATA_HOME/realpen/profiles``, else
``~/.local/share/realpen/profiles``). A bundle there is a sub-folder holding ``profile.json``
or a ``.zip`` file.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from realpen.errors import RealPenError, fail
from realpen.profile.bundle import PenProfile, load_profile
from realpen.profile.schema import PROFILE_JSON

log = logging.getLogger(__name__)

__all__ = ["profile_locations", "list_profiles", "resolve_profile"]


def profile_locations(extra: list[Path] | None = None) -> list[tuple[str, Path]]:
    """Where profiles are looked for, in order: ("bundled", folder), ("user", folder), then
    ("extra", folder) for each of ``extra``."""
    from realpen.io.paths import user_profiles_dir
    from realpen.pens import bundled_dir

    places = [("bundled", bundled_dir()), ("user", user_profiles_dir())]
    places += [("extra", Path(p)) for p in (extra or [])]
    return places


def list_profiles(extra: list[Path] | None = None) -> list[tuple[str, Path]]:
    """Every profile found: (where, bundle path), bundled first; later names do not hide earlier.

    A bundle is a sub-folder holding ``profile.json`` or a ``.zip`` file. Nothing is read
    here: a broken bundle is found like any other and refused by
    :func:`~realpen.profile.bundle.load_profile`, which callers that list many profiles catch
    per bundle.

    Raises:
        RealPenError: a folder of ``extra`` that is not a folder or cannot be listed (naming
            it). The user's folder, optional, is skipped with a logged warning instead.
    """
    found = []
    for where, folder in profile_locations(extra):
        try:
            if not folder.is_dir():
                if where == "extra":  # asked for by name: say so (the others are optional)
                    raise fail(folder, "no such folder of profiles")
                continue
            for entry in sorted(folder.iterdir()):
                # lexists: a profile.json that is there at all (a symlink, even dangling, or a
                # special file) makes a bundle to load, and so to refuse by name, not to omit.
                if (entry.is_dir() and os.path.lexists(entry / PROFILE_JSON)) \
                        or entry.suffix == ".zip":
                    found.append((where, entry))
        except OSError as error:  # not permitted to list or to look inside
            if where != "extra":  # the user's own folder is optional: the others still work
                log.warning("%s: cannot list this profiles folder (%s); its profiles are "
                            "skipped", folder, error.strerror or error)
                continue
            raise fail(folder, f"cannot list this profiles folder ({error.strerror or error})") \
                from None
    return found


def resolve_profile(name_or_path: str | os.PathLike,
                    extra: list[Path] | None = None) -> PenProfile:
    """Load a profile by path (folder or ``.zip``) or by name (bundled, user, extra folders).

    Example:
        >>> resolve_profile("pencil").name
        'pencil'

    Raises:
        RealPenError: no such profile (the known names are listed), or a broken bundle.
    """
    name_or_path = os.fspath(name_or_path)
    if not os.fspath(name_or_path).strip():  # Path("") is the current folder: not meant
        raise fail("profile", "the name or path is empty; give a pen's name or a bundle")
    candidate = Path(name_or_path)
    try:
        exists = candidate.exists()
    except OSError:  # something is there that cannot be looked at: load_profile names it
        exists = True
    if exists or candidate.suffix == ".zip" or os.sep in name_or_path:
        return load_profile(candidate)
    for _, path in list_profiles(extra):
        if path.name == name_or_path or path.stem == name_or_path:
            return load_profile(path)
    names = sorted({path.stem for _, path in list_profiles(extra)})
    raise RealPenError(f"{name_or_path}: no such profile (known: {', '.join(names) or 'none'})")
