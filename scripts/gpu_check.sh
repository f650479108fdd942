#!/usr/bin/env bash
# The project's GPU checks in one run, for a GPU machine without internet (issue #31).
#
#   scripts/gpu_wheels.sh            # here, with internet: the cp312 wheels into .whl/
#   scripts/gpu_check.sh [OUTDIR]    # there, in the repository root, with .whl/ carried
#
# Installs the carried wheels into /tmp/site (nothing else on the machine changes), then runs,
# each under its own time limit so one that hangs cannot take the others' time:
#   1. the GPU-marked tests (CUDA detection, CUDA synthesis, pillar net, NMS, target
#      assignment, training with amp),
#   2. `python -m benchmarks gpu` (its figures go to BENCHMARKS.md, with the card's name),
#   3. `python -m benchmarks training` on the paper model (host-side ms per step, DataLoader
#      workers on the GPU).
# Logs land in OUTDIR (default gpu-check/); the exit status is the first failure's.
set -u
out=${1:-${OUT:-gpu-check}}
mkdir -p "$out"
export PYTHONUNBUFFERED=1
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site:$PWD
# The checkout runs uninstalled: configs/ installs as sim2radar.configs (pyproject's
# package-dir), so link it there for the run (this copy of the tree only) and unlink after.
if [ ! -e sim2radar/configs ]; then
    ln -s ../configs sim2radar/configs && trap 'rm -f sim2radar/configs' EXIT
fi
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader | tee "$out/machine.txt"
python3 -c "import torch, mitsuba, drjit; print('torch', torch.__version__, 'cuda', torch.version.cuda,
'mitsuba', mitsuba.__version__, 'drjit', drjit.__version__)" | tee -a "$out/machine.txt"
status=0
run() {  # run LIMIT_S LOG CMD...: one step, its output teed to OUTDIR/LOG
    local limit=$1 log=$2; shift 2
    echo "== $* (limit ${limit} s)"
    timeout "$limit" "$@" 2>&1 | tee "$out/$log"
    local rc=${PIPESTATUS[0]}
    echo "== exit $rc"
    [ "$status" -ne 0 ] || status=$rc
}
run "${GPU_CHECK_TESTS_S:-120}" tests.log python3 -m pytest -q -p no:cacheprovider \
    -o addopts="-ra --import-mode=importlib" -m gpu \
    tests/detect/test_anchors.py tests/detect/test_model.py tests/detect/test_losses_nms.py \
    tests/detect/test_train.py tests/radar/test_signal.py tests/radar/test_detection_torch.py
run "${GPU_CHECK_BENCH_S:-330}" bench_gpu.log python3 -m benchmarks gpu
SIM2RADAR_BENCH_PROFILES=paper SIM2RADAR_BENCH_ROUNDS=1 \
    run "${GPU_CHECK_TRAINING_S:-80}" bench_training.log python3 -m benchmarks training
exit "$status"
