#!/usr/bin/env bash
# Build the documentation site (MkDocs + mkdocstrings) with every check on: `mkdocs build
# --strict`, so a broken link, a broken cross-reference between docstrings or a malformed
# docstring section fails the build.
# Usage: bash scripts/build-docs.sh [SITE_DIR]    (default: site/, which git ignores)
# Quiet when the build passes; otherwise prints mkdocs' output and exits 1. Needs the `docs`
# extra in .venv: .venv/bin/pip install -e '.[docs]'.
set -euo pipefail
cd "$(dirname "$0")/.."
site="${1:-site}"
if [ ! -x .venv/bin/mkdocs ]; then
    echo "build-docs: .venv/bin/mkdocs is missing; install the docs extra:" \
         ".venv/bin/pip install -e '.[docs]'" >&2
    exit 1
fi
log="$(mktemp)"
trap 'rm -f "$log"' EXIT
# Not --quiet: it would hide the warnings that --strict counts. NO_MKDOCS_2_WARNING silences the
# theme's banner about its successor.
if ! NO_MKDOCS_2_WARNING=1 .venv/bin/mkdocs build --strict --clean --site-dir "$site" >"$log" 2>&1; then
    cat "$log" >&2
    exit 1
fi
