#!/usr/bin/env bash
# Set up a virtual environment with RealPen and its test dependencies, lint, then run every test.
# Usage: bash scripts/test.sh [pytest arguments]
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e '.[test]'
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
# Lint first: the rules are in pyproject.toml ([tool.ruff]); any finding stops the run.
.venv/bin/ruff check --no-cache .
# Two workers (pytest-xdist): the browser and server tests mostly wait, so two cores finish the
# suite in about two thirds of the time one takes.
exec .venv/bin/python -m pytest -n 2 "$@"
