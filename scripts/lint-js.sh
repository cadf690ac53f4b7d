#!/usr/bin/env bash
# Check the live page's JavaScript (src/realpen/live/static): ESLint (eslint.config.js) and the
# JSDoc types of the pen modules with tsc --noEmit (tsconfig.json). The tools come from the npm
# registry at the versions package-lock.json pins, into node_modules/ (npm ci).
# Usage: bash scripts/lint-js.sh     (any finding exits non-zero)
# Without npm it says so in one line and exits 0: the page needs no build, and nothing else in
# the suite needs Node.js.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v npm >/dev/null 2>&1; then
    echo "npm not found: JavaScript lint skipped"
    exit 0
fi
npm ci --no-audit --no-fund --silent --prefer-offline
npm run --silent lint
npm run --silent typecheck
