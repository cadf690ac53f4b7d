"""Shared fixtures: the real-data folders beside the repository and a CLI runner."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

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
    """Run ``realpen ARGS`` in a fresh interpreter and capture its output."""
    return subprocess.run([sys.executable, "-m", "realpen.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=300)


def assert_clean_failure(result: subprocess.CompletedProcess, names: str) -> None:
    """Exit code 2, one line on stderr that mentions ``names``, and no traceback."""
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert names in lines[0], lines[0]
    assert "Traceback" not in result.stderr
