"""Shared fixtures: the real-data folders beside the repository and a CLI runner."""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
import traceback
from pathlib import Path
from unittest import mock

import pytest

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
HATT_DIR = SHARED / "data" / "hatt_models"
LMT_DIR = SHARED / "data" / "lmt108_sound"


def require_dir(path: Path) -> Path:
    """Skip the calling test, saying why, when a real-data folder is not there."""
    if not path.is_dir() or not any(path.iterdir()):
        pytest.skip(f"real data not available: {path} is absent (it is never bundled; "
                    f"see shared/data/README.md)")
    return path


@pytest.fixture
def hatt_dir() -> Path:
    return require_dir(HATT_DIR)


@pytest.fixture
def lmt_dir() -> Path:
    return require_dir(LMT_DIR)


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run ``realpen ARGS`` in this interpreter and capture its output and exit code.

    The command line's own entry point (:func:`realpen.cli.main`) runs as the console script
    would, with ``sys.argv`` set and stdout/stderr captured; the result has the shape of a
    :class:`subprocess.CompletedProcess` so end-to-end tests can use :func:`run_cli_process`.
    """
    from realpen.cli import main

    stdout, stderr = io.StringIO(), io.StringIO()
    argv = ["realpen", *map(str, args)]
    code = 0
    previous = os.getcwd()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr), \
            mock.patch.object(sys, "argv", argv):
        try:
            if cwd is not None:
                os.chdir(cwd)
            main()
        except SystemExit as exit_:
            code = exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else 1)
        except BaseException:  # a traceback escaped main(): report it like the interpreter would
            stderr.write(traceback.format_exc())
            code = 1
        finally:
            os.chdir(previous)
    return subprocess.CompletedProcess(argv, code, stdout.getvalue(), stderr.getvalue())


def run_cli_process(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run ``python -m realpen ARGS`` in a fresh interpreter (for the few end-to-end tests)."""
    return subprocess.run([sys.executable, "-m", "realpen", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=300)


def assert_clean_failure(result: subprocess.CompletedProcess, names: str) -> None:
    """Exit code 2, one line on stderr that mentions ``names``, and no traceback."""
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert names in lines[0], lines[0]
    assert "Traceback" not in result.stderr


# ---- the live app in-process (tests/test_live_*.py) ------------------------------------------

@pytest.fixture
def store_path(tmp_path):
    """Where the in-process live app's stroke store goes."""
    return tmp_path / "strokes.sqlite3"


@pytest.fixture
def client(tmp_path, store_path, monkeypatch):
    """The live app in-process (FastAPI's TestClient), loopback settings, a fresh store."""
    from fastapi.testclient import TestClient

    from realpen.live.app import LiveSettings, create_app

    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    app = create_app(LiveSettings.loopback(store=store_path))
    with TestClient(app, base_url="http://127.0.0.1") as test_client:
        yield test_client
