#!/usr/bin/env bash
# luckyao: the two commands of the README, and two for developers.
#   bash run.sh study [snakemake args...]   set up .venv, run the default study -> figures/
#   bash run.sh test  [pytest args...]      set up .venv, lint, run the test suite
#   bash run.sh lint                        set up .venv, lint and format checks only
#   bash run.sh docs  [sphinx args...]      set up .venv (docs extra), build docs/_build/html
#   bash run.sh lock                        refresh requirements.lock and requirements-docs.lock
# Needs only Python >= 3.11 with pip; installs everything into .venv, at the exact versions of
# requirements.lock (the docs' tools: requirements-docs.lock).
set -euo pipefail
cd "$(dirname "$0")"

PYTHON="${PYTHON:-python3}"
VENV=.venv
EXTRAS=test   # pyproject's extras of the .venv: the study's (workflow, plots, fits) and the suite's
# the same BLAS kernels on every machine, so the same numbers (src/luckyao/__init__.py)
export OPENBLAS_CORETYPE="${OPENBLAS_CORETYPE:-Haswell}"

# The checkout a .venv was built for: the path its stamp records (a stamp of an older run.sh
# is empty: the folder of the src/ its editable install names), empty if unknown.
venv_checkout() {
    local stamp="$VENV/.luckyao-installed" recorded="" pth
    if [ -f "$stamp" ]; then
        recorded="$(head -n 1 "$stamp")"
    fi
    if [ -z "$recorded" ]; then
        for pth in "$VENV"/lib/python*/site-packages/__editable__.luckyao-*.pth; do
            if [ -f "$pth" ]; then
                recorded="$(dirname "$(head -n 1 "$pth")")"
            fi
        done
    fi
    printf '%s' "$recorded"
}

setup() {
    local here built
    here="$(pwd -P)"
    # A .venv built for another checkout (this one copied, cp -a, or moved with its .venv):
    # its editable install and its scripts name that checkout's paths, so it would run the
    # other checkout's code, or fail to import any. Rebuilt here, for this checkout.
    if [ -e "$VENV" ] || [ -L "$VENV" ]; then
        built="$(venv_checkout)"
        if [ "$built" != "$here" ]; then
            echo "luckyao: .venv was built for ${built:-another checkout}, not $here: rebuilding it" >&2
            rm -rf "$VENV"
        fi
    fi
    if [ ! -x "$VENV/bin/python" ]; then
        "$PYTHON" -m venv "$VENV"
    fi
    # reinstall only when the package metadata changed (or the .venv is new); the stamp
    # records the checkout it was built for
    local stamp="$VENV/.luckyao-installed"
    if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ requirements.lock -nt "$stamp" ]; then
        "$VENV/bin/python" -m pip install --quiet --upgrade pip
        # every package at the version requirements.lock pins (a package the lock misses would
        # come unpinned: the suite compares the .venv with the lock); byte-compiled on both
        # cores by compileall, not one file at a time by pip (~20 s less), with the package's
        # own source (its editable install is not compiled, and every job imports it); a file
        # that does not compile (as pip would) only runs uncompiled
        echo "luckyao: installing .venv from requirements.lock" >&2
        "$VENV/bin/python" -m pip install --quiet --no-compile -r requirements.lock -e ".[$EXTRAS]"
        "$VENV/bin/python" -m compileall -q -j 0 src \
            "$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')" > /dev/null || true
        printf '%s\n' "$here" > "$stamp"
    fi
}

# The documentation's tools too (Sphinx and its extensions: pyproject's docs extra).
setup_docs() {
    setup
    local stamp="$VENV/.luckyao-docs-installed"
    if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ requirements-docs.lock -nt "$stamp" ]; then
        echo "luckyao: installing the docs' tools from requirements-docs.lock" >&2
        "$VENV/bin/python" -m pip install --quiet --no-compile -r requirements.lock -r requirements-docs.lock \
            -e ".[$EXTRAS,docs]"
        touch "$stamp"
    fi
}

# The locks, refreshed: the newest releases pyproject.toml allows, installed into a new
# throwaway environment, as pip freeze lists them (the package itself left out); the docs'
# lock holds what the docs extra adds, at the versions requirements.lock keeps.
lock() {
    local tmp
    tmp="$(mktemp -d)"
    trap 'rm -rf "$tmp"' RETURN
    "$PYTHON" -m venv "$tmp/venv"
    "$tmp/venv/bin/python" -m pip install --quiet --upgrade pip
    "$tmp/venv/bin/python" -m pip install --quiet --no-compile -e ".[$EXTRAS]"   # -e: no build/ left here
    {
        echo "# Every package of run.sh's .venv (pyproject's extras $EXTRAS), exact versions"
        echo "# (Python $("$tmp/venv/bin/python" -c 'import platform; print(platform.python_version())')); made by \`bash run.sh lock\`."
        "$tmp/venv/bin/python" -m pip freeze --exclude luckyao
    } > requirements.lock
    "$tmp/venv/bin/python" -m pip freeze --exclude luckyao > "$tmp/base.txt"
    "$tmp/venv/bin/python" -m pip install --quiet --no-compile -c requirements.lock -e ".[$EXTRAS,docs]"
    {
        echo "# What the docs extra adds to requirements.lock, exact versions; made by \`bash run.sh lock\`."
        "$tmp/venv/bin/python" -m pip freeze --exclude luckyao | grep -vxF -f "$tmp/base.txt"
    } > requirements-docs.lock
    echo "luckyao: wrote requirements.lock ($(grep -cv '^#' requirements.lock) packages) and" \
        "requirements-docs.lock ($(grep -cv '^#' requirements-docs.lock))" >&2
}

# The habits CI keeps: the code linted and formatted (ruff), the rules formatted (snakefmt)
# and linted (snakemake --lint, but for the two lints kept by design: tools/lint_rules.py).
lint() {
    "$VENV/bin/python" -m ruff check src tests benchmarks docs tools
    "$VENV/bin/python" -m ruff format --check --quiet src tests benchmarks docs tools
    "$VENV/bin/python" -m snakefmt --check Snakefile workflow/rules
    "$VENV/bin/python" tools/lint_rules.py
}

command="${1:-}"
shift || true
case "$command" in
    study)
        setup
        # After a hard kill Snakemake keeps its lock and jobs leave *.partial files: both
        # are cleared when no run of the workflow uses the study folder (this one, or -d /
        # --directory in any form): every Snakemake of the workflow holds a lock on it
        # (src/luckyao/jobs/live_run.py), however started. Then Snakemake runs.
        exec "$VENV/bin/python" -m luckyao.jobs.live_run "$@"
        ;;
    test)
        setup
        lint
        # the test files shared out over LUCKYAO_TEST_WORKERS processes (2: CI's cores), each
        # file's tests in one process (its module fixtures, the tiny studies, made once)
        exec "$VENV/bin/python" -m pytest -n "${LUCKYAO_TEST_WORKERS:-2}" --dist loadfile "$@"
        ;;
    lint)
        setup
        lint
        ;;
    lock)
        lock
        ;;
    docs)
        setup_docs
        # warnings are errors; the gallery's examples (docs/examples/) run during the build
        exec "$VENV/bin/python" -m sphinx -W --keep-going -b html docs docs/_build/html "$@"
        ;;
    *)
        echo "usage: bash run.sh study|test|lint|docs|lock [args...]" >&2
        exit 2
        ;;
esac
