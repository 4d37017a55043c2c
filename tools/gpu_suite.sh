#!/usr/bin/env bash
# The GPU checks of pdsim, in one script for a borrowed GPU machine (Python 3.12 with numpy, scipy, tqdm and pytest,
# no registry): unpacks the wheels packed by tools/gpu_wheels.sh into one site folder, puts this tree on the path beside it, then
# runs each stage under a time limit so that the whole script ends within SUITE_BUDGET_S (default 480 s):
#
#   1. calibration: the pre-flight's cost constants measured on the GPU
#      (tools/preflight_calibration.py --cost --device cuda --write --out $OUT/cost_calibration_cuda.json);
#   2. compare: the pre-flight's estimates against gallery scenes run on the GPU at their preview settings
#      (tools/preflight_calibration.py --compare --device cuda);
#   3. default_scene: `pdsim run --device cuda --profile` twice (the second with a warm kernel cache; the first too when
#      an earlier stage compiled the kernels), the run reports in the log;
#   4. tests: the CUDA tests of tests/test_gpu_path.py (CPU/CUDA agreement for peridynamics, FEM and lattice, a
#      captured CUDA graph against frames launched step by step, the device fragment labeller on CUDA);
#   4b. contact: the CUDA cases of the contact and rigid-body tests ($CONTACT_TESTS: momentum through a rigid ball's
#      impact on peridynamic and FEM blocks, restitution and friction, FEM-FEM contact, the rigid and static
#      hand-off), the same physics assertions as on the CPU;
#   5. agree: a gallery scene's preview frames on the CPU and on CUDA, compared frame by frame (tools/bench_gpu.py
#      agree $AGREE);
#   6. pd_throughput: the peridynamic throughput of an elastic block of N_PD^3 particles (tools/bench_gpu.py pd).
# STAGES names the stages to run (default: all).
#
# Results go to $OUT (default ./gpu_out), at most 8 files: gpu_suite.json (each stage's exit status and seconds, the
# device), cost_calibration_cuda.json, and each stage's log (the default scene's log ends with its run report).
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
SUITE_BUDGET_S="${SUITE_BUDGET_S:-480}"
N_PD="${N_PD:-100}"
PD_FRAMES="${PD_FRAMES:-3}"
PD_SUBSTEPS="${PD_SUBSTEPS:-20}"
REPEATS="${REPEATS:-2}"
SITE="${SITE:-/tmp/pdsim_gpu_site}"
STAGES="${STAGES:-calibration compare default_scene tests contact agree pd_throughput}"  # the stages to run (names below)
CONTACT_TESTS="${CONTACT_TESTS:-tests/test_rigid_restitution.py tests/test_rigid_bodies.py tests/test_contact_law.py
    tests/test_fem_contact.py tests/test_rigid_handoff.py tests/test_rigid_handoff_static.py}"
COMPARE="${COMPARE:-}"  # the compare stage's scenes (empty: the tool's default list)
AGREE="${AGREE:-fem_slab_crack}"  # the agree stage's scene
START=$(date +%s)
mkdir -p "$OUT" "$STAGE"

log() { echo "[gpu_suite $(($(date +%s) - START))s] $*"; }

# -- the wheels: parts arrive over several commands and wait in $STAGE --------------------------------------------------
stage_parts() {
    if [ -f "$WHEELS/manifest.sha256" ]; then
        cp "$WHEELS/manifest.sha256" "$STAGE/"
    fi
    for part in "$WHEELS"/part[0-9][0-9]/site.tar.[0-9][0-9]; do
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
    local sum
    sum=$(grep -v '^#' "$STAGE/manifest.sha256" | awk '$2 == "site.tar" {print $1}')
    cat "$STAGE"/site.tar.[0-9][0-9] > "$STAGE/site.tar"
    if [ "$(sha256sum "$STAGE/site.tar" | cut -d' ' -f1)" != "$sum" ]; then
        log "site.tar does not match its manifest sum"
        return 1
    fi
    rm -rf "$SITE" "$STAGE/wheels" && mkdir -p "$SITE" "$STAGE/wheels"
    tar -xf "$STAGE/site.tar" -C "$STAGE/wheels"
    rm -f "$STAGE/site.tar"
    for wheel in "$STAGE"/wheels/*.whl; do
        "$PYTHON" -m zipfile -e "$wheel" "$SITE" || return 1
    done
    log "site: $(tr '\n' ' ' < "$STAGE/wheels/wheels.txt")"
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
PY="$PYTHON"
# pdsim as pyproject.toml installs it (kernels/ as pdsim.kernels) without a build step: a link in this copy of the tree
[ -e pdsim/kernels ] || ln -s ../kernels pdsim/kernels
export PYTHONPATH="$ROOT:$SITE"
"$PY" -c "import warp, pdsim, pxr; warp.init(); print('warp', warp.__version__, 'cuda devices', warp.get_cuda_device_count())" \
    >> "$OUT/install.log" 2>&1 || {
    log "pdsim does not import (install.log)"
    exit 5
}
log "installed: $(tail -1 "$OUT/install.log")"

# -- stages ----------------------------------------------------------------------------------------------------------
STAGES_JSON=""
run_stage() { # name, limit [s], command...
    local name="$1" limit="$2"
    shift 2
    case " $STAGES " in
        *" $name "*) ;;
        *) return ;;
    esac
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
run_stage calibration 230 "$PY" tools/preflight_calibration.py --cost --device cuda --repeats "$REPEATS" --write \
    --out "$OUT/cost_calibration_cuda.json"
# shellcheck disable=SC2086  # COMPARE is a list of scene names (empty: the tool's default list)
run_stage compare 150 "$PY" tools/preflight_calibration.py --compare $COMPARE --device cuda
# the default scene twice (bash's time: the whole process's wall time)
run_stage default_scene 70 bash -c "mkdir -p /tmp/pdsim_default && for run in first second; do TIMEFORMAT=\"\$run: wall %R s\"; \
    time \"$PY\" -m pdsim.cli run --device cuda --profile --out /tmp/pdsim_default/\$run.usdc || exit 1; \
    cat /tmp/pdsim_default/\$run.report.json; done"
run_stage tests 80 "$PY" -m pytest -q -rs -p no:cacheprovider tests/test_gpu_path.py -k "cuda"
# shellcheck disable=SC2086  # CONTACT_TESTS is a list of test files
run_stage contact 150 "$PY" -m pytest -q -rs -p no:cacheprovider --durations=10 $CONTACT_TESTS -k "cuda"
run_stage agree 150 "$PY" tools/bench_gpu.py agree "$AGREE" --device cuda --json-out "$OUT/agree.json"
run_stage pd_throughput 40 "$PY" tools/bench_gpu.py pd --n "$N_PD" --frames "$PD_FRAMES" --substeps "$PD_SUBSTEPS" \
    --device cuda

DEVICE=$(nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>/dev/null | head -1)
WARP=$("$PY" -c "import warp; print(warp.__version__)" 2>/dev/null)
cat > "$OUT/gpu_suite.json" << EOF
{${STAGES_JSON} "device": "${DEVICE}", "warp": "${WARP}", "seconds": $(($(date +%s) - START))}
EOF
log "done: $OUT/gpu_suite.json"
cat "$OUT/gpu_suite.json"
