"""A throwaway PostgreSQL server: :func:`running_postgres` (the test suite's ``postgres_server``
fixture and the benchmarks use it).

``initdb`` in a fresh temporary folder, listening only on a Unix socket there, run as the
``postgres`` user when the caller is root (the server refuses root), stopped and removed at the end. It hands
back conftest's :class:`PostgresServer` (``url(name)``, ``new_database()``, ``execute(sql)``).
conftest's own ``postgres_bin`` and ``PostgresServer`` are imported when the server starts, not
when this module is imported, so that conftest may itself use this module.
"""

from __future__ import annotations

import contextlib
import os
import shlex
import shutil
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["PostgresUnavailable", "running_postgres"]

PORT = 5432  # only the socket's file name: nothing listens on TCP


class PostgresUnavailable(RuntimeError):
    """PostgreSQL cannot be run here (not installed, or root without a ``postgres`` user); the
    message says why."""


@contextlib.contextmanager
def running_postgres() -> Iterator:
    """Start a PostgreSQL server for the block; yields conftest's ``PostgresServer``.

    The server keeps its durability settings (``fsync`` and ``synchronous_commit`` on); only
    ``initdb``'s own files skip their sync.

    Raises:
        PostgresUnavailable: PostgreSQL is not installed, or cannot run as another user.
        RuntimeError: the server did not start (with the end of its log).
    """
    from conftest import POSTGRES_MISSING, PostgresServer, postgres_bin

    folder_bin = postgres_bin()
    if folder_bin is None:
        raise PostgresUnavailable(POSTGRES_MISSING)
    # The socket's path must stay short (~100 bytes), and as root pytest's folders are private.
    folder = Path(tempfile.mkdtemp(prefix="realpen-pg-"))
    data, log = folder / "data", folder / "server.log"
    as_user: list[str] | None = []
    if os.geteuid() == 0:
        import pwd

        try:
            account = pwd.getpwnam("postgres")
        except KeyError:
            shutil.rmtree(folder, ignore_errors=True)
            raise PostgresUnavailable("PostgreSQL refuses to run as root and there is no postgres "
                                      "user (the Debian package postgresql makes it)") from None
        os.chown(folder, account.pw_uid, account.pw_gid)
        runuser = shutil.which("runuser")
        as_user = [runuser, "-u", "postgres", "--"] if runuser else None

    def run(*command: str) -> None:
        if as_user is None:  # root without runuser: su takes one shell command
            command = ("su", "postgres", "-c", " ".join(shlex.quote(part) for part in command))
        # LC_ALL=C: a locale the machine has not generated would stop the server starting.
        subprocess.run([*(as_user or []), *command], check=True, capture_output=True, text=True,
                       timeout=120, env={**os.environ, "LC_ALL": "C"})

    try:
        run(str(folder_bin / "initdb"), "-D", str(data), "-A", "trust", "-U", "postgres",
            "-E", "UTF8", "--no-locale", "--no-sync")
        run(str(folder_bin / "pg_ctl"), "-D", str(data), "-l", str(log), "-w", "-t", "60",
            "-o", f"-k {folder} -c listen_addresses='' -p {PORT}", "start")
    except subprocess.CalledProcessError as error:
        detail = log.read_text(errors="replace")[-2000:] if log.exists() else ""
        shutil.rmtree(folder, ignore_errors=True)
        raise RuntimeError(f"the PostgreSQL server did not start: {error.stderr}\n{detail}") \
            from None
    try:
        yield PostgresServer(folder, PORT)
    finally:
        with contextlib.suppress(subprocess.SubprocessError):
            run(str(folder_bin / "pg_ctl"), "-D", str(data), "-m", "fast", "-w", "stop")
        shutil.rmtree(folder, ignore_errors=True)
