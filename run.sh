#!/usr/bin/env bash
# luckyao: the two commands of the README.
#   bash run.sh study [snakemake args...]   set up .venv, run the default study -> figures/
#   bash run.sh test  [pytest args...]      set up .venv, run the test suite
# Needs only Python >= 3.11 with pip; installs everything into .venv.
set -euo pipefail
cd "$(dirname "$0")"

PYTHON="${PYTHON:-python3}"
VENV=.venv

setup() {
    if [ ! -x "$VENV/bin/python" ]; then
        "$PYTHON" -m venv "$VENV"
    fi
    # reinstall only when the package metadata changed
    local stamp="$VENV/.luckyao-installed"
    if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
        "$VENV/bin/python" -m pip install --quiet --upgrade pip
        "$VENV/bin/python" -m pip install --quiet -e ".[test]"
        touch "$stamp"
    fi
}

command="${1:-}"
shift || true
case "$command" in
    study)
        setup
        # After a hard kill Snakemake keeps its lock and jobs leave *.partial files:
        # when no Snakemake of this checkout is running, clear both before starting
        # (in the study folder: this one, or the one given by -d / --directory).
        local_dir=.
        args=("$@")
        for ((i = 0; i < ${#args[@]}; i++)); do
            case "${args[i]}" in
                -d|--directory) local_dir="${args[i + 1]:-.}" ;;
                --directory=*) local_dir="${args[i]#--directory=}" ;;
            esac
        done
        # (matched by this checkout's absolute path: another checkout's runs do not count)
        snakemake="$PWD/$VENV/bin/snakemake"
        if ! pgrep -f "$snakemake" > /dev/null; then
            if [ -n "$(ls -A "$local_dir/.snakemake/locks" 2> /dev/null)" ]; then
                echo "luckyao: no Snakemake is running here; removing the stale lock of a killed run" >&2
                "$snakemake" --unlock -d "$local_dir" > /dev/null
            fi
            find "$local_dir/results" -name '*.partial' -delete 2> /dev/null || true
        fi
        exec "$snakemake" "$@"
        ;;
    test)
        setup
        exec "$VENV/bin/python" -m pytest "$@"
        ;;
    *)
        echo "usage: bash run.sh study|test [args...]" >&2
        exit 2
        ;;
esac
