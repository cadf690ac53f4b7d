"""The distribution a user installs: the wheel and the sdist build, carry the licence, the type
marker and the package data (and no ``__pycache__``), and the wheel works in a fresh venv.

The fresh venv reaches the already installed dependencies through a plain path line (a ``.pth``
holding the test venv's ``site-packages``), which adds them to ``sys.path`` without running the
checkout's editable-install hook: ``realpen`` itself can only come from the wheel, and the tests
check that it does. Installing numpy, scipy and the rest again would test PyPI, not RealPen.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import urllib.request
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def dist(tmp_path_factory) -> Path:
    """``python -m build`` (sdist, then the wheel from the sdist) of the checkout, each in an
    isolated environment with only pyproject.toml's build requirements; uv (which
    scripts/test.sh installs) makes those environments in a fraction of pip's time."""
    out = tmp_path_factory.mktemp("dist")
    uv = importlib.util.find_spec("uv") is not None or shutil.which("uv") is not None
    result = subprocess.run([sys.executable, "-m", "build", "--installer", "uv" if uv else "pip",
                             "--outdir", str(out), str(ROOT)], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return out


@pytest.fixture(scope="module")
def wheel_venv(dist, tmp_path_factory) -> Path:
    """A fresh venv with the built wheel installed (dependencies shared, see the module doc)."""
    home = tmp_path_factory.mktemp("wheelenv")
    venv.create(home, with_pip=False)
    python = home / "bin" / "python"
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                          capture_output=True, text=True, check=True).stdout.strip()
    (Path(site) / "shared_dependencies.pth").write_text(sysconfig.get_path("purelib") + "\n")
    [wheel] = dist.glob("realpen-*.whl")
    # pip of the test venv installs into the fresh one (--python), entry point script included.
    result = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install",
                             "--quiet", "--no-deps", "--no-index", str(wheel)],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-3000:]
    return home


def test_wheel_and_sdist_carry_the_licence_type_marker_and_data_without_bytecode(dist):
    [wheel] = dist.glob("realpen-*.whl")
    [sdist] = dist.glob("realpen-*.tar.gz")
    names = zipfile.ZipFile(wheel).namelist()
    assert not [name for name in names if "__pycache__" in name or name.endswith(".pyc")]
    for needed in ("realpen/py.typed", "realpen/study/migrations/script.py.mako",
                   "realpen/study/designs/study1.yaml", "realpen/live/static/index.html",
                   "realpen/pens/bundled/pencil/profile.json", "realpen/examples/synthetic_pen_3axis.npz"):
        assert needed in names
    assert any(name.endswith(".dist-info/licenses/LICENSE") for name in names)
    [metadata] = [name for name in names if name.endswith(".dist-info/METADATA")]
    text = zipfile.ZipFile(wheel).read(metadata).decode()
    assert "License-Expression: BSD-3-Clause" in text
    with tarfile.open(sdist) as archive:
        members = archive.getnames()
    assert any(member.endswith("/LICENSE") for member in members)
    assert not [member for member in members if "__pycache__" in member]


def _run(home: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "REALPEN_HOME": str(home / "realpen-home")}
    env.pop("PYTHONPATH", None)
    return subprocess.run([str(home / "bin" / "realpen"), *args], capture_output=True, text=True,
                          env=env, cwd=home, timeout=120)


def test_the_installed_wheel_runs_from_its_own_files(wheel_venv):
    where = subprocess.run([str(wheel_venv / "bin" / "python"), "-c",
                            "import realpen, realpen.pens; print(realpen.__file__)"],
                           capture_output=True, text=True, cwd=wheel_venv, check=True).stdout
    assert Path(where.strip()).is_relative_to(wheel_venv), where
    version = _run(wheel_venv, "--version")
    assert version.returncode == 0 and "0.1.0" in version.stdout, version
    listed = _run(wheel_venv, "profile", "list")
    assert listed.returncode == 0, listed.stderr
    for pen in ("pencil", "ballpoint", "marker"):
        assert pen in listed.stdout


def test_serve_from_the_wheel_answers_with_the_bundled_pens(wheel_venv):
    from live_support import serve

    with serve(wheel_venv, timeout=60, program=[str(wheel_venv / "bin" / "realpen")]) as served:
        base = served.base.rstrip("/")
        with urllib.request.urlopen(f"{base}/api/profiles", timeout=30) as reply:
            names = {profile["name"] for profile in json.load(reply)["profiles"]}
        assert {"pencil", "ballpoint", "marker"} <= names
        with urllib.request.urlopen(f"{base}/", timeout=30) as reply:
            assert reply.status == 200 and b"<html" in reply.read().lower()
