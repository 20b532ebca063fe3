#!/usr/bin/env bash
# Set up a virtual environment and run every check CI runs: ruff, the test
# suite (pytest, slow tests and benchmark smoke sizes included), the docstring
# examples of the library and of the built-in plugins, and the strict docs build.
# Usage: bash scripts/test.sh [extra pytest args]
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
VENV=${SKELAGNOSTIC_VENV:-.venv}
if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -m venv "$VENV"
fi
# constraints.txt pins the CPU build of torch (an unpinned torch pulls CUDA wheels).
"$VENV/bin/python" -m pip install --quiet --disable-pip-version-check \
  -c constraints.txt -e ".[test,bench,docs,export]"
echo "== ruff"
"$VENV/bin/ruff" check src tests benchmarks plugins scripts
"$VENV/bin/ruff" format --check src tests benchmarks plugins scripts
echo "== pytest"
"$VENV/bin/python" -m pytest -n 2 --durations=15 "$@"
echo "== doctests (the docstring examples of the library and of the built-in plugins)"
"$VENV/bin/python" -m pytest -q -n 2 -p no:cacheprovider --doctest-modules src/skelagnostic \
  plugins/*/src
echo "== docs"
NO_MKDOCS_2_WARNING=1 "$VENV/bin/mkdocs" build --strict --quiet --site-dir "$(mktemp -d)"
