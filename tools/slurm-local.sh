#!/usr/bin/env bash
# The tiny test study through the SLURM profile on a real one-node SLURM cluster, checked
# against a local run of the same study.
#
#   bash tools/slurm-local.sh          # as root on Debian; exit status 0 when every check passed
#
# It installs slurm-wlm and munge with apt when they are missing, and the SLURM executor plugin
# into .venv (pip install -e ".[slurm]"); writes a private one-node configuration for this
# machine (its CPUs and 90 % of its memory, free ports, everything under one temporary folder);
# starts munged, slurmctld and slurmd on it; runs tests/data/tiny.yaml locally and then through
# profiles/slurm (partition filled in, no account: the cluster has no accounting); checks that
# every job but the short local rules (`all`, figures, FITS export) went through sbatch and finished COMPLETED in the
# controller's job-completion log, and that the outputs equal the local run's; and stops the
# daemons it started, on success, failure or interrupt. While it runs, /etc/slurm/slurm.conf is a
# link to its configuration (it refuses to run where that file exists). LUCKYAO_SLURM_KEEP=1
# keeps the folder.
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PY="${PYTHON:-$REPO/.venv/bin/python}"
export PATH="$PATH:/usr/sbin:/sbin"

say() { echo "slurm-local: $*"; }
die() { echo "slurm-local: FAILED: $*" >&2; exit 1; }

[ "$(id -u)" = 0 ] || die "must run as root (it installs packages and starts munged, slurmctld and slurmd)"
[ -x "$PY" ] || die "no Python at $PY: run 'bash run.sh test' once to create .venv, or set PYTHON"

# --- prerequisites -------------------------------------------------------------------------------
missing=()
for tool in slurmctld slurmd sbatch squeue sinfo scontrol scancel munged mungekey; do
    command -v "$tool" > /dev/null || missing+=("$tool")
done
if [ ${#missing[@]} -gt 0 ]; then
    command -v apt-get > /dev/null || die "missing ${missing[*]} and no apt-get to install slurm-wlm and munge"
    say "installing slurm-wlm and munge with apt (missing: ${missing[*]})"
    apt-get update -qq > /dev/null
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge > /dev/null
fi
if ! "$PY" -c "import snakemake_executor_plugin_slurm" 2> /dev/null; then
    say "installing the SLURM executor plugin: pip install -e \"$REPO[slurm]\""
    "$PY" -m pip install --quiet -e "$REPO[slurm]"
fi

# --- a private one-node cluster ------------------------------------------------------------------
STATE="$(mktemp -d /tmp/luckyao-slurm.XXXXXX)"
chmod 755 "$STATE"
mkdir -p "$STATE/munge" "$STATE/ctld" "$STATE/slurmd"
chmod 700 "$STATE/munge"
CONF="$STATE/slurm.conf"
export SLURM_CONF="$CONF"
PIDS=()          # daemons started here, in start order
NAMES=()

stop_daemons() {
    local status=$?
    trap - EXIT INT TERM
    if [ ${#PIDS[@]} -gt 0 ]; then
        # cancel what is left and let slurmd end the job steps before the daemons go
        if [[ " ${NAMES[*]} " == *" slurmctld "* ]]; then
            scancel --quiet --full --partition=luckyao 2> /dev/null || true
            for _ in $(seq 30); do
                [ -z "$(squeue -h -t RUNNING,PENDING,COMPLETING 2> /dev/null)" ] && break
                sleep 1
            done
        fi
        for ((i = ${#PIDS[@]} - 1; i >= 0; i--)); do
            kill -TERM "${PIDS[i]}" 2> /dev/null || true
            for _ in $(seq 50); do
                kill -0 "${PIDS[i]}" 2> /dev/null || break
                sleep 0.2
            done
            kill -KILL "${PIDS[i]}" 2> /dev/null || true
            wait "${PIDS[i]}" 2> /dev/null || true
        done
        say "stopped the daemons it started: ${NAMES[*]} (pids ${PIDS[*]})"
    fi
    if [ "${LINKED_CONF:-0}" = 1 ] && [ "$(readlink "$SYSTEM_CONF")" = "$CONF" ]; then
        rm -f "$SYSTEM_CONF"
    fi
    if [ "$status" != 0 ]; then
        for f in "$STATE"/slurmctld.log "$STATE"/slurmd.log "$STATE"/slurm-run.log; do
            [ -f "$f" ] && { echo "--- last lines of $f"; tail -n 25 "$f"; }
        done
        say "kept $STATE for inspection"
    elif [ "${LUCKYAO_SLURM_KEEP:-0}" = 1 ]; then
        say "kept $STATE"
    else
        rm -rf "$STATE"
    fi
    if [ "$status" = 0 ]; then say "PASSED"; else say "FAILED (exit status $status)"; fi
    exit "$status"
}
CHILD=""        # the long step running now (a Snakemake run), ended first on a signal
on_signal() {
    if [ -n "$CHILD" ]; then
        kill -TERM "$CHILD" 2> /dev/null || true
        wait "$CHILD" 2> /dev/null || true
    fi
    exit "$1"
}
trap stop_daemons EXIT
trap 'on_signal 130' INT
trap 'on_signal 143' TERM

run_in() {  # run_in DIR LOG COMMAND...: in DIR, output to LOG, in the background and waited for,
            # so that a signal is handled at once (the traps' output goes to this script's)
    local dir=$1 log=$2 status=0
    shift 2
    (cd "$dir" && exec "$@") > "$log" 2>&1 &
    CHILD=$!
    wait "$CHILD" || status=$?
    CHILD=""
    return "$status"
}

start() {  # start NAME COMMAND...: a daemon in the foreground, as a child of this script
    local name=$1
    shift
    "$@" > "$STATE/$name.out" 2>&1 &
    PIDS+=($!)
    NAMES+=("$name")
}

HOST="$(hostname -s)"
read -r CTLD_PORT SLURMD_PORT < <("$PY" -c '
import socket
socks = [socket.socket() for _ in range(2)]
for s in socks:
    s.bind(("127.0.0.1", 0))
print(*(s.getsockname()[1] for s in socks))')
NODE="$(slurmd -C | head -n 1)"                       # this machine's CPUs and topology
MEMORY_MB="$(awk '/^MemTotal/ {printf "%d", $2 / 1024 * 0.9}' /proc/meminfo)"
NODE="$(echo "$NODE" | sed -E "s/RealMemory=[0-9]+/RealMemory=$MEMORY_MB/") NodeAddr=127.0.0.1 State=UNKNOWN"

mungekey --create --keyfile="$STATE/munge/munge.key" 2> /dev/null \
    || dd if=/dev/urandom of="$STATE/munge/munge.key" bs=1 count=1024 status=none
chmod 400 "$STATE/munge/munge.key"
MUNGE_SOCKET="$STATE/munge/munge.socket"

cat > "$CONF" <<EOF
# One-node SLURM for tools/slurm-local.sh (written at run time, linked from /etc/slurm/slurm.conf while it runs)
ClusterName=luckyao
SlurmctldHost=$HOST(127.0.0.1)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
AuthType=auth/munge
AuthInfo=socket=$MUNGE_SOCKET
CredType=cred/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
MinJobAge=600
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/slurmd
SlurmctldPidFile=$STATE/slurmctld.pid
SlurmdPidFile=$STATE/slurmd.pid
SlurmctldLogFile=$STATE/slurmctld.log
SlurmdLogFile=$STATE/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
SlurmUser=root
JobCompType=jobcomp/filetxt
JobCompLoc=$STATE/jobcomp.log
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
$NODE
PartitionName=luckyao Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
EOF

# The job step plugin runs srun inside each job without SLURM_CONF (it drops SLURM_* variables),
# so srun reads the default /etc/slurm/slurm.conf: a link to this configuration while it runs.
SYSTEM_CONF=/etc/slurm/slurm.conf
if [ -L "$SYSTEM_CONF" ] && [ ! -e "$SYSTEM_CONF" ] && [[ "$(readlink "$SYSTEM_CONF")" == /tmp/luckyao-slurm.* ]]; then
    rm -f "$SYSTEM_CONF"     # left by a run of this script that was killed
fi
if [ -e "$SYSTEM_CONF" ] || [ -L "$SYSTEM_CONF" ]; then
    die "$SYSTEM_CONF exists: this machine has a SLURM configuration of its own, which this test would shadow"
fi
mkdir -p /etc/slurm
ln -s "$CONF" "$SYSTEM_CONF"
LINKED_CONF=1

start munged munged --foreground --force --key-file="$STATE/munge/munge.key" --socket="$MUNGE_SOCKET" \
    --pid-file="$STATE/munge/munged.pid" --log-file="$STATE/munge/munged.log" --seed-file="$STATE/munge/munged.seed"
for _ in $(seq 50); do [ -S "$MUNGE_SOCKET" ] && break; sleep 0.2; done
[ -S "$MUNGE_SOCKET" ] || die "munged did not start: $(cat "$STATE/munged.out")"
start slurmctld slurmctld -D -i -f "$CONF"
start slurmd slurmd -D -f "$CONF" -N "$HOST"
state=""
for _ in $(seq 60); do
    state="$(sinfo -h -N -o %T 2> /dev/null || true)"
    [ "$state" = idle ] && break
    sleep 1
done
[ "$state" = idle ] || die "the node did not come up idle (state '${state:-none}')"
say "$(sinfo --version), one node $HOST: $(echo "$NODE" | grep -o 'CPUs=[0-9]*') RealMemory=$MEMORY_MB MB," \
    "ports $CTLD_PORT/$SLURMD_PORT, daemons ${NAMES[*]} (pids ${PIDS[*]})"

# --- the tiny study, locally and through SLURM ---------------------------------------------------
study_dir() {  # a study folder with the tiny study as its config
    mkdir -p "$1/config"
    cp "$REPO/tests/data/tiny.yaml" "$1/config/config.yaml"
}
study_dir "$STATE/local-run"
study_dir "$STATE/slurm-run"
cp -r "$REPO/profiles/slurm" "$STATE/profile"
sed -i -E 's/^( *slurm_partition:).*/\1 "luckyao"/; /^ *slurm_account:/d' "$STATE/profile/config.yaml"

say "local run of tests/data/tiny.yaml (--cores 2) ..."
t0=$(date +%s)
run_in "$STATE/local-run" "$STATE/local-run.log" \
    "$PY" -m snakemake -s "$REPO/Snakefile" -d "$STATE/local-run" --cores 2 \
    || { tail -n 30 "$STATE/local-run.log"; die "the local run failed"; }
LOCAL_S=$(($(date +%s) - t0))

say "SLURM run of tests/data/tiny.yaml (--workflow-profile profiles/slurm, partition luckyao) ..."
t0=$(date +%s)
run_in "$STATE/slurm-run" "$STATE/slurm-run.log" \
    "$PY" -m snakemake -s "$REPO/Snakefile" -d "$STATE/slurm-run" \
    --workflow-profile "$STATE/profile" --slurm-status-command squeue \
    --slurm-init-seconds-before-status-checks 2 --slurm-keep-successful-logs \
    || die "the SLURM run failed (log: $STATE/slurm-run.log)"
SLURM_S=$(($(date +%s) - t0))

say "report of the SLURM run: snakemake --report report.html"
run_in "$STATE" "$STATE/report.log" \
    "$PY" -m snakemake -s "$REPO/Snakefile" -d "$STATE/slurm-run" --report "$STATE/slurm-run/report.html" \
    || { tail -n 20 "$STATE/report.log"; die "the report failed"; }

# --- checks --------------------------------------------------------------------------------------
"$PY" - "$STATE" "$LOCAL_S" "$SLURM_S" <<'EOF'
import re
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import xarray as xr

state, local_s, slurm_s = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
problems = []

# 1. every job but the short local rules went through sbatch, and SLURM ran each to COMPLETED
log = (state / "slurm-run.log").read_text()
submitted = dict(re.findall(r"Job (\d+) has been submitted with SLURM jobid (\d+)", log))
local_rules = re.findall(r"^localrule (\w+):", log, re.M)
steps = re.findall(r"(\d+) of (\d+) steps \(100%\) done", log)
total = int(steps[-1][1]) if steps else -1
rules = {}
for path in (state / "slurm-run" / ".snakemake" / "slurm_logs").rglob("*.log"):
    rules[path.stem] = path.relative_to(state / "slurm-run" / ".snakemake" / "slurm_logs").parts[0][len("rule_"):]
completion = {}
jobcomp = state / "jobcomp.log"
for line in (jobcomp.read_text().splitlines() if jobcomp.exists() else []):
    fields = dict(item.split("=", 1) for item in line.split() if "=" in item)
    completion[fields.get("JobId")] = fields.get("JobState")
slurm_ids = sorted(submitted.values(), key=int)
controller = re.findall(r"_slurm_rpc_submit_batch_job: JobId=(\d+)", (state / "slurmctld.log").read_text())
not_completed = {i: completion.get(i, "not in the job-completion log") for i in slurm_ids if completion.get(i) != "COMPLETED"}
if total < 0:
    problems.append("the SLURM run did not report 100% of its steps done")
SHORT = {"all", "all_cases", "figure_settings", "figure", "export"}  # localrules: seconds-long, beside Snakemake
if set(local_rules) - SHORT or "all" not in local_rules:
    problems.append(f"jobs that ran on the submit host instead of through SLURM: {sorted(set(local_rules) - SHORT)}")
if len(submitted) != total - len(local_rules):
    problems.append(f"{len(submitted)} jobs went through sbatch, expected {total - len(local_rules)} "
                    "(all jobs but the local rules)")
if sorted(controller, key=int) != slurm_ids:
    problems.append(f"the controller logged batch submissions {controller}, Snakemake reported {slurm_ids}")
if not_completed:
    problems.append(f"SLURM jobs not COMPLETED: {not_completed}")
by_rule = Counter(rules.get(i, "?") for i in slurm_ids)
print(f"slurm-local: SLURM run: {total} jobs, {len(submitted)} through sbatch (SLURM job ids {slurm_ids[0] if slurm_ids else '-'}"
      f"-{slurm_ids[-1] if slurm_ids else '-'}; {len(controller)} batch submissions in the controller's log), {sum(completion.get(i) == 'COMPLETED' for i in slurm_ids)} COMPLETED in the "
      f"controller's job-completion log, {len(local_rules)} local ({', '.join(local_rules)}); {slurm_s} s "
      f"(local run: {local_s} s)")
print("slurm-local: through sbatch by rule: " + ", ".join(f"{rule} {n}" for rule, n in sorted(by_rule.items())))

# 2. the outputs equal the local run's
def equal(a, b):
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind in "fc" and b.dtype.kind in "fc":
        return a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
    return a.shape == b.shape and bool(np.all(a == b))

TIMING = {"history", "build_seconds"}    # when a file was made and how long its build took


def same_attrs(a, b):
    return set(a) == set(b) and all(equal(a[k], b[k]) for k in a)

local, slurm = state / "local-run", state / "slurm-run"
names = sorted(str(p.relative_to(local)) for p in [*local.glob("results/**/*.nc"), *local.glob("figures/*.nc")])
names_slurm = sorted(str(p.relative_to(slurm)) for p in [*slurm.glob("results/**/*.nc"), *slurm.glob("figures/*.nc")])
if names != names_slurm:
    problems.append(f"different output files: local only {sorted(set(names) - set(names_slurm))}, "
                    f"SLURM only {sorted(set(names_slurm) - set(names))}")
compared = different = 0
for name in sorted(set(names) & set(names_slurm)):
    with xr.open_dataset(local / name) as a, xr.open_dataset(slurm / name) as b:
        diff = [v for v in sorted(set(a.variables) | set(b.variables))
                if v not in a.variables or v not in b.variables or not equal(a[v].values, b[v].values)
                or not same_attrs(a[v].attrs, b[v].attrs)]
        attrs = [k for k in sorted((set(a.attrs) | set(b.attrs)) - TIMING)
                 if k not in a.attrs or k not in b.attrs or not equal(a.attrs[k], b.attrs[k])]
    if diff or attrs:
        problems.append(f"{name} differs: variables {diff}, global attributes {attrs}")
        different += 1
    compared += 1
pngs = sorted(p.name for p in local.glob("figures/*.png"))
png_equal = sum((local / "figures" / n).read_bytes() == (slurm / "figures" / n).read_bytes()
                for n in pngs if (slurm / "figures" / n).exists())
if png_equal != len(pngs):
    problems.append(f"only {png_equal} of {len(pngs)} figure PNGs are byte-identical")
print(f"slurm-local: outputs equal the local run's: {compared - different} of "
      f"{compared} netCDF datasets (every variable, coordinate and attribute but the creation time and build timing), "
      f"{png_equal} of {len(pngs)} figure PNGs byte for byte")
# 3. the report holds every figure with its caption
import yaml  # noqa: E402

figures = list(yaml.safe_load((slurm / "config" / "config.yaml").read_text())["figures"])
report = (slurm / "report.html").read_text()
in_report = [f for f in figures if f'"figures/{f}.html"' in report and f"Figure <strong>{f}</strong>" in report]
if in_report != figures:
    problems.append(f"figures missing from the report or without caption: {sorted(set(figures) - set(in_report))}")
print(f"slurm-local: report.html holds {len(in_report)} of {len(figures)} figures, each with its caption")
for problem in problems:
    print(f"slurm-local: PROBLEM: {problem}")
sys.exit(1 if problems else 0)
EOF
