#!/usr/bin/env bash
# The GPU checks of pdsim, in one script for a borrowed GPU machine (Python 3.12 with numpy and scipy, no registry):
# installs the wheels packed by tools/gpu_wheels.sh and pdsim from this tree, then, each stage under a time limit so
# that the whole script ends within SUITE_BUDGET_S (default 330 s):
#
#   1. the CUDA tests of tests/test_gpu_path.py: CPU/CUDA agreement for peridynamics, FEM and lattice, a captured
#      CUDA graph replayed against frames launched step by step, the device fragment labeller on CUDA;
#   2. the peridynamic throughput of an elastic block of N_PD^3 particles (default 100: 1e6), step by step and as a
#      graph (tools/bench_gpu.py pd);
#   3. scenes/four_walls.py at spacing 0.0025 m for WALLS_FRAMES frames, timed (tools/bench_gpu.py four-walls).
#
# Results go to $OUT (default ./gpu_out): gpu_suite.json (each stage's exit status and seconds, the device), tests.log
# and tests.xml, pd_throughput.json, four_walls.json, and each stage's log.
#
#   bash tools/gpu_suite.sh stage    # a command that carries some of the parts: keep them for the next command
#   bash tools/gpu_suite.sh          # the command that carries the last part: reassemble, install, run
#   bash tools/gpu_suite.sh check    # reassemble and verify the parts only (no install, nothing run)
set -uo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
MODE="${1:-run}"
OUT="${OUT:-$ROOT/gpu_out}"
PYTHON="${PYTHON:-python3}"
WHEELS="${WHEELS:-$ROOT/.gpu_wheels}"
STAGE="${STAGE:-$HOME/.pdsim_gpu_wheels}"
SUITE_BUDGET_S="${SUITE_BUDGET_S:-330}"
N_PD="${N_PD:-100}"
PD_FRAMES="${PD_FRAMES:-3}"
PD_SUBSTEPS="${PD_SUBSTEPS:-20}"
WALLS_SPACING="${WALLS_SPACING:-0.0025}"
WALLS_FRAMES="${WALLS_FRAMES:-3}"
START=$(date +%s)
mkdir -p "$OUT" "$STAGE"

log() { echo "[gpu_suite $(($(date +%s) - START))s] $*"; }

# -- the wheels: parts arrive over several commands and wait in $STAGE --------------------------------------------------
stage_parts() {
    if [ -f "$WHEELS/manifest.sha256" ]; then
        cp "$WHEELS/manifest.sha256" "$STAGE/"
    fi
    for part in "$WHEELS"/part[0-9][0-9]/wheels.tar.[0-9][0-9]; do
        [ -f "$part" ] || continue
        cp "$part" "$STAGE/"
    done
    if [ ! -f "$STAGE/manifest.sha256" ]; then
        log "no manifest in $WHEELS or $STAGE (carry .gpu_wheels/manifest.sha256; make it with tools/gpu_wheels.sh)"
        return 2
    fi
    local missing=0 name sum
    while read -r sum name; do
        case "$name" in
            part*/*) ;;
            *) continue ;;
        esac
        if [ -f "$STAGE/$(basename "$name")" ] &&
            [ "$(sha256sum "$STAGE/$(basename "$name")" | cut -d' ' -f1)" = "$sum" ]; then
            log "have $(basename "$name")"
        else
            log "missing $(basename "$name") (carry .gpu_wheels/$(dirname "$name"))"
            missing=$((missing + 1))
        fi
    done < <(grep -v '^#' "$STAGE/manifest.sha256")
    return "$missing"
}

assemble() {
    local tar_sum
    tar_sum=$(grep -v '^#' "$STAGE/manifest.sha256" | awk '$2 == "wheels.tar" {print $1}')
    cat "$STAGE"/wheels.tar.[0-9][0-9] > "$STAGE/wheels.tar"
    if [ "$(sha256sum "$STAGE/wheels.tar" | cut -d' ' -f1)" != "$tar_sum" ]; then
        log "wheels.tar does not match its manifest sum"
        return 1
    fi
    rm -rf "$STAGE/wheels" && mkdir -p "$STAGE/wheels"
    tar -xf "$STAGE/wheels.tar" -C "$STAGE/wheels"
    rm -f "$STAGE/wheels.tar"
    log "wheels: $(tr '\n' ' ' < "$STAGE/wheels/wheels.txt")"
}

case "$MODE" in
    stage)
        stage_parts
        exit 0
        ;;
    check)
        stage_parts || exit 3
        assemble || exit 4
        exit 0
        ;;
    run) ;;
    *)
        echo "usage: bash tools/gpu_suite.sh [run|stage|check]" >&2
        exit 64
        ;;
esac

if ! stage_parts; then
    log "not all parts have arrived: run 'bash tools/gpu_suite.sh stage' with the others first"
    exit 3
fi
assemble || exit 4

# -- install ---------------------------------------------------------------------------------------------------------
export PIP_DISABLE_PIP_VERSION_CHECK=1 PYTHONUNBUFFERED=1
# a virtual environment over the system's numpy and scipy; where the interpreter has no venv module, the system
# interpreter itself (the machine is given back afterwards), said in the log
VENV="$HOME/.pdsim_gpu_venv"
PIP_EXTRA=()
if [ -x "$VENV/bin/python" ] || "$PYTHON" -m venv --system-site-packages "$VENV" > "$OUT/install.log" 2>&1; then
    PY="$VENV/bin/python"
else
    log "no venv module: installing into $PYTHON's own site-packages"
    PY="$PYTHON"
    PIP_EXTRA=(--break-system-packages)
fi
(cd "$STAGE/wheels" && "$PY" -m pip install --quiet --no-index --no-deps "${PIP_EXTRA[@]}" ./*.whl) \
    >> "$OUT/install.log" 2>&1 || {
    log "installing the wheels failed (install.log)"
    exit 5
}
"$PY" -m pip install --quiet --no-index --no-deps --no-build-isolation "${PIP_EXTRA[@]}" . \
    >> "$OUT/install.log" 2>&1 || {
    log "installing pdsim failed (install.log)"
    exit 5
}
log "installed"

# -- stages ----------------------------------------------------------------------------------------------------------
STAGES_JSON=""
run_stage() { # name, limit [s], command...
    local name="$1" limit="$2"
    shift 2
    local left=$((SUITE_BUDGET_S - ($(date +%s) - START) - 5))
    if [ "$left" -lt 20 ]; then
        log "$name: skipped (the suite's budget is spent)"
        STAGES_JSON="$STAGES_JSON\"$name\": {\"rc\": null, \"seconds\": 0, \"skipped\": true},"
        return
    fi
    [ "$limit" -gt "$left" ] && limit="$left"
    log "$name: up to ${limit}s"
    local t0 rc
    t0=$(date +%s)
    timeout --kill-after=5 "$limit" "$@" > "$OUT/$name.log" 2>&1
    rc=$?
    log "$name: exit $rc after $(($(date +%s) - t0))s"
    STAGES_JSON="$STAGES_JSON\"$name\": {\"rc\": $rc, \"seconds\": $(($(date +%s) - t0)), \"limit\": $limit},"
}

export WARP_CACHE_PATH="${WARP_CACHE_PATH:-$HOME/.cache/pdsim_warp}"
run_stage tests 150 "$PY" -m pytest -q -rs -p no:cacheprovider tests/test_gpu_path.py -k "cuda" \
    --junitxml="$OUT/tests.xml"
run_stage pd_throughput 110 "$PY" tools/bench_gpu.py pd --n "$N_PD" --frames "$PD_FRAMES" --substeps "$PD_SUBSTEPS" \
    --device cuda --json-out "$OUT/pd_throughput.json"
run_stage four_walls 100 "$PY" tools/bench_gpu.py four-walls --spacing "$WALLS_SPACING" --frames "$WALLS_FRAMES" \
    --device cuda --json-out "$OUT/four_walls.json"

DEVICE=$(nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>/dev/null | head -1)
WARP=$("$PY" -c "import warp; print(warp.__version__)" 2>/dev/null)
cat > "$OUT/gpu_suite.json" << EOF
{${STAGES_JSON} "device": "${DEVICE}", "warp": "${WARP}", "seconds": $(($(date +%s) - START))}
EOF
log "done: $OUT/gpu_suite.json"
cat "$OUT/gpu_suite.json"
