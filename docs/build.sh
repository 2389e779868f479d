#!/usr/bin/env bash
# The documentation site: bash docs/build.sh [sphinx-build args...] -> docs/_build/html/index.html
# Sets up .venv as run.sh does (with the docs extra), then builds with warnings as errors;
# the gallery's examples (docs/examples/) run during the build.
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON="${PYTHON:-python3}"
VENV=.venv
# the same BLAS kernels on every machine, so the same numbers (src/luckyao/__init__.py)
export OPENBLAS_CORETYPE="${OPENBLAS_CORETYPE:-Haswell}"

if [ ! -x "$VENV/bin/python" ]; then
    "$PYTHON" -m venv "$VENV"
fi
# (re)install when the package metadata changed since the last docs install
stamp="$VENV/.luckyao-docs-installed"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    "$VENV/bin/python" -m pip install --quiet --upgrade pip
    "$VENV/bin/python" -m pip install --quiet --no-compile -e ".[test,docs]"
    touch "$stamp"
fi

exec "$VENV/bin/sphinx-build" -W --keep-going -b html docs docs/_build/html "$@"
