"""Where profiles live: the bundled pens, the user's profiles folder, and extra folders.

The user's profiles folder is :func:`realpen.io.paths.user_profiles_dir`
(``$REALPEN_HOME/profiles``, else ``$XDG_DATA_HOME/realpen/profiles``, else
``~/.local/share/realpen/profiles``). A bundle there is a sub-folder holding ``profile.json``
or a ``.zip`` file.

One resolver: :func:`resolve_profile` is the only place that tells a profile's name from a
bundle's path, and every way in — :func:`load_profile` (``rp.load_profile``), the command line,
the live app's catalog — goes through it, so one mistake gets one message wherever it is made.
The bundled pens are found as package data of :mod:`realpen.pens` (by the package's name,
without importing it: the pens are built from profiles, one layer up).
"""

from __future__ import annotations

import logging
import os
from importlib.resources import files
from pathlib import Path

from realpen.errors import RealPenError, fail
from realpen.profile.bundle import PenProfile, read_bundle
from realpen.profile.schema import PROFILE_JSON

log = logging.getLogger(__name__)

__all__ = ["BUNDLED_PACKAGE", "bundled_profiles_dir", "profile_locations", "list_profiles",
           "resolve_profile", "load_profile"]

BUNDLED_PACKAGE = "realpen.pens"
"""The package whose ``bundled`` folder holds the pens that ship with RealPen."""


def bundled_profiles_dir() -> Path:
    """The folder of the bundled profiles, one sub-folder per pen (the same folder as
    :func:`realpen.pens.bundled_dir`)."""
    return Path(str(files(BUNDLED_PACKAGE) / "bundled"))


def profile_locations(extra: list[Path] | None = None) -> list[tuple[str, Path]]:
    """Where profiles are looked for, in order: ("bundled", folder), ("user", folder), then
    ("extra", folder) for each of ``extra``."""
    from realpen.io.paths import user_profiles_dir

    places = [("bundled", bundled_profiles_dir()), ("user", user_profiles_dir())]
    places += [("extra", Path(p)) for p in (extra or [])]
    return places


def list_profiles(extra: list[Path] | None = None) -> list[tuple[str, Path]]:
    """Every profile found: (where, bundle path), bundled first; later names do not hide earlier.

    A bundle is a sub-folder holding ``profile.json`` or a ``.zip`` file. Nothing is read
    here: a broken bundle is found like any other and refused by
    :func:`~realpen.profile.bundle.read_bundle`, which callers that list many profiles catch
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


def _names_a_path(text: str, path: Path) -> bool:
    """Whether a profile reference is a path (else a name): something is there, or it has a
    folder separator, or it ends in ``.zip`` (in any case)."""
    try:
        if path.exists():
            return True
    except OSError:  # something is there that cannot be looked at: the reader names it
        return True
    return os.sep in text or (os.altsep or os.sep) in text or path.suffix.lower() == ".zip"


def resolve_profile(name_or_path: str | os.PathLike,
                    extra: list[Path] | None = None) -> PenProfile:
    """Load a profile by path (folder or ``.zip``) or by name (bundled, user, extra folders).

    The one resolver (see the module doc): a reference that names something there, holds a
    folder separator or ends in ``.zip`` is a path, read by
    :func:`~realpen.profile.bundle.read_bundle`; anything else is a name, looked up in
    :func:`list_profiles` (a bundle's folder name, or a zip's name without ``.zip``).

    Args:
        name_or_path: a pen's name (``"pencil"``) or a bundle's folder or ``.zip``.
        extra: more folders of profiles to look in, after the bundled and the user's.

    Example:
        >>> resolve_profile("pencil").name
        'pencil'

    Raises:
        RealPenError: an empty reference, no such profile (the known names are listed; a
            path: "folder or .zip"), or a broken bundle.
    """
    text = os.fspath(name_or_path)
    if not text.strip():  # Path("") is the current folder: not what was meant
        raise fail("profile", "the name or path is empty; give a pen's name or a bundle")
    path = Path(text)
    if _names_a_path(text, path):
        return read_bundle(path)
    found = list_profiles(extra)
    for _, bundle in found:
        if bundle.name == text or bundle.stem == text:
            return read_bundle(bundle)
    names = sorted({bundle.stem for _, bundle in found})
    raise RealPenError(f"{text}: no such profile (known: {', '.join(names) or 'none'})")


def load_profile(path: str | os.PathLike) -> PenProfile:
    """Load and check a pen profile: a bundle (folder or ``.zip``) of format 1, 2 or 3, or an
    installed profile by name.

    The same as :func:`resolve_profile` without extra folders, so both word every mistake
    alike.

    Args:
        path: the bundle's folder or ``.zip``; a bare name that is no file here (``"pencil"``)
            is looked up among the installed profiles.

    Example:
        >>> load_profile("pencil").meta.tactile
        TactilePattern(15 sub-patterns × 100 ms, 10 components each, 8000 Hz)

    Raises:
        RealPenError: a missing file, an unknown format version, a schema violation, WAVs
            that do not match the JSON, a file over its limit, a damaged, encrypted or
            oversized zip — each as one line naming the bundle (no other exception, whatever
            the bundle's bytes); an unknown name (the known names are listed).
    """
    return resolve_profile(path)
