#!/usr/bin/env bash
# Set up a virtual environment with RealPen and its test dependencies, lint, then run every test.
# Usage: bash scripts/test.sh [pytest arguments]
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e '.[test]'
# The browser tests drive Debian's Chromium; install it when missing and we may.
if [ ! -x /usr/bin/chromium ]; then
    if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
        apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y chromium
    else
        echo "note: /usr/bin/chromium is missing and installing it needs root and apt-get;" \
             "the browser tests will be skipped (install the Debian package 'chromium')." >&2
    fi
fi
# Lint first: the rules are in pyproject.toml ([tool.ruff]); any finding stops the run.
.venv/bin/ruff check --no-cache .
exec .venv/bin/python -m pytest "$@"
