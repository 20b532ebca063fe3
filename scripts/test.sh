#!/usr/bin/env bash
# Set up a virtual environment and run every check CI runs: ruff, the test
# suite (pytest, slow tests and benchmark smoke sizes included), the docstring
# examples of the library and of the built-in plugins, and the strict docs build.
#
# Every stage runs even when an earlier one failed; a table at the end gives
# each stage's status and seconds, and the exit status is non-zero when any
# stage failed (or the set-up did, which leaves nothing to run).
# Usage: bash scripts/test.sh [extra pytest args]
set -uo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
VENV=${SKELAGNOSTIC_VENV:-.venv}

NAMES=()
STATUSES=()
SECONDS_TAKEN=()

# stage NAME COMMAND [ARG ...]: run one stage, record its status and wall time.
stage() {
  local name=$1 start end status
  shift
  echo "== $name"
  start=$(date +%s.%N)
  "$@"
  status=$?
  end=$(date +%s.%N)
  NAMES+=("$name")
  if [ "$status" -eq 0 ]; then STATUSES+=("ok"); else STATUSES+=("FAILED (exit $status)"); fi
  SECONDS_TAKEN+=("$(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.1f", b - a }')")
  return "$status"
}

report() {
  local i failed=0
  echo
  printf '%-28s %-18s %9s\n' "stage" "status" "seconds"
  printf '%-28s %-18s %9s\n' "-----" "------" "-------"
  for i in "${!NAMES[@]}"; do
    printf '%-28s %-18s %9s\n' "${NAMES[$i]}" "${STATUSES[$i]}" "${SECONDS_TAKEN[$i]}"
    [ "${STATUSES[$i]}" = ok ] || failed=$((failed + 1))
  done
  if [ "$failed" -ne 0 ]; then
    echo "scripts/test.sh: $failed of ${#NAMES[@]} stages failed" >&2
    return 1
  fi
  echo "scripts/test.sh: all ${#NAMES[@]} stages passed"
}

setup() {
  if [ ! -x "$VENV/bin/python" ]; then
    "$PY" -m venv "$VENV" || return
  fi
  # constraints.txt pins the CPU build of torch (an unpinned torch pulls CUDA wheels).
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check \
    -c constraints.txt -e ".[test,bench,docs,export]"
}

if ! stage "setup (venv, pip install)" setup; then
  report
  exit 1
fi
stage "ruff check" "$VENV/bin/ruff" check src tests benchmarks plugins scripts
stage "ruff format --check" "$VENV/bin/ruff" format --check src tests benchmarks plugins scripts
stage "pytest" "$VENV/bin/python" -m pytest -n 2 --durations=15 "$@"
# the docstring examples of the library and of the built-in plugins
stage "doctests" "$VENV/bin/python" -m pytest -q -n 2 -p no:cacheprovider --doctest-modules \
  src/skelagnostic plugins/*/src
stage "docs build" env NO_MKDOCS_2_WARNING=1 "$VENV/bin/mkdocs" build --strict --quiet \
  --site-dir "$(mktemp -d)"
report
