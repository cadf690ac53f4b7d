#!/usr/bin/env bash
# Set up a virtual environment with RealPen and its test dependencies, lint, then run the tests.
# Usage: bash scripts/test.sh [--fast] [pytest arguments]
#
# Tiers (pytest markers, registered in pyproject.toml and applied in tests/conftest.py and the
# test modules):
#   browser   Debian's Chromium driven by Playwright (the live page, the study pages, Web Serial)
#   postgres  a PostgreSQL server of the run's own (the store on PostgreSQL)
#   firmware  the pen firmware under the MicroPython Unix port, the Due's C core built with cc
#   slow      a `realpen serve` or Python subprocess, or seconds of computing
# Without --fast every test runs (about 5 minutes on 2 cores). With --fast only the tests that
# carry none of the four run: the library and the CLI in-process (about a minute).
# Other arguments go to pytest, e.g. `bash scripts/test.sh --fast -k stats` or
# `bash scripts/test.sh -m browser`.
set -euo pipefail
cd "$(dirname "$0")/.."
tier=()
if [ "${1:-}" = "--fast" ]; then
    shift
    tier=(-m "not browser and not postgres and not firmware and not slow")
fi
# The page's JavaScript (ESLint, tsc) and, in the full run, the documentation site (mkdocs
# --strict) are checked beside the set-up and the tests, which leave a core idle much of the
# time: the JavaScript needs no venv and starts first, the docs once the venv is installed. Each
# writes to a log that is shown only when it fails.
checks_dir="$(mktemp -d)"
trap 'rm -rf "$checks_dir"' EXIT
js_pid=
if command -v npm >/dev/null 2>&1; then
    bash scripts/lint-js.sh >"$checks_dir/js.log" 2>&1 &
    js_pid=$!
else
    echo "note: npm not found: the JavaScript lint (ESLint, tsc) is skipped" >&2
fi
# The tests start hundreds of Python processes (servers, the CLI, workers): let them keep the
# bytecode they compile, in this venv and the checkout, even where the environment says not to
# (PYTHONDONTWRITEBYTECODE); without it each would compile numpy, scipy and pandas again.
unset PYTHONDONTWRITEBYTECODE
python3 -m venv .venv
# uv (from PyPI) installs the same packages as pip in seconds instead of a minute and a half; pip
# does it where uv cannot be had.
if .venv/bin/python -m pip install --quiet --disable-pip-version-check uv >/dev/null 2>&1; then
    .venv/bin/uv pip install --quiet --python .venv/bin/python -e '.[test,docs]'
else
    .venv/bin/python -m pip install --quiet --upgrade pip
    .venv/bin/python -m pip install --quiet -e '.[test,docs]'
fi
docs_pid=
if [ "${#tier[@]}" -eq 0 ]; then
    bash scripts/build-docs.sh "$checks_dir/site" >"$checks_dir/docs.log" 2>&1 &
    docs_pid=$!
fi
# The browser tests drive Debian's Chromium, the store tests start a PostgreSQL server of
# their own (initdb in a temporary folder), and the Arduino Due firmware's C core is compiled
# with cc: install what is missing when we may, with one apt-get update for all.
missing=()
if ! command -v cc >/dev/null 2>&1; then
    missing+=(gcc libc6-dev)
fi
if [ ! -x /usr/bin/chromium ]; then
    missing+=(chromium)
fi
if ! command -v initdb >/dev/null 2>&1 && ! ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1; then
    missing+=(postgresql)
fi
if [ "${#missing[@]}" -gt 0 ]; then
    if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
        apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y "${missing[@]}"
    else
        echo "note: missing Debian package(s) ${missing[*]}, and installing them needs root and" \
             "apt-get; the tests that need them will be skipped (chromium: the browser tests;" \
             "postgresql: the store tests on PostgreSQL; gcc: the Due firmware tests)." >&2
    fi
fi
# Lint first: the rules are in pyproject.toml ([tool.ruff], [tool.importlinter]); any finding
# stops the run.
.venv/bin/ruff check --no-cache .
.venv/bin/lint-imports --no-cache >/dev/null || .venv/bin/lint-imports --no-cache
# Two workers (pytest-xdist): the browser and server tests mostly wait, so two cores finish the
# suite in about two thirds of the time one takes. --dist loadfile runs each module on one
# worker, so its module-scoped set-up (servers, analyses, renders) is built once; the modules
# are handed out longest first (the order tests/conftest.py gives them; see
# pytest_collection_modifyitems there).
status=0
.venv/bin/python -m pytest -n 2 --dist loadfile --no-loadscope-reorder "${tier[@]}" "$@" || status=$?
if [ -n "$js_pid" ] && ! wait "$js_pid"; then
    echo "JavaScript lint failed (bash scripts/lint-js.sh):" >&2; cat "$checks_dir/js.log" >&2; status=1
fi
if [ -n "$docs_pid" ] && ! wait "$docs_pid"; then
    echo "documentation build failed (bash scripts/build-docs.sh):" >&2; cat "$checks_dir/docs.log" >&2
    status=1
fi
exit "$status"
