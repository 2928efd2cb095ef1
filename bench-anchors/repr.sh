#!/usr/bin/env bash
# The representation benchmark: burn (flex, ours: learner/examples/repr_bench.rs)
# against PyTorch running the same architecture (bench-anchors/torch-repr/bench.py),
# alternately, ROUNDS rounds, on the same machine in one run.
#   training: one Adam step of the Full Model at batch 64, 128×128 px, 2 threads,
#   with the training kernels (learner-kernels, "ours-conv")
#   and with burn's own (--kernels burn, "burn-flex")
#   inference: z means at batch 1 and 64, one thread: burn's encode ("burn-flex")
#   and the inference API's CPU path ("ours-fast", learner::models::fast)
# PyTorch is installed from PyPI into .venv-torch (a benchmark anchor, not a
# dependency of the project). Results: docs/performance.md.
# Usage: bench-anchors/repr.sh [ROUNDS] [OUT.jsonl]
set -euo pipefail
cd "$(dirname "$0")/.."
ROUNDS=${1:-3}
OUT=${2:-target/repr-bench.jsonl}
source bench-anchors/repr-setup.sh
: > "$OUT"
for r in $(seq 1 "$ROUNDS"); do
    echo "== round $r of $ROUNDS"
    RAYON_NUM_THREADS=2 $BIN train 64 5 | tee -a "$OUT"
    RAYON_NUM_THREADS=2 $BIN --kernels burn train 64 5 | tee -a "$OUT"
    $PY train 64 5 2 | tee -a "$OUT"
    RAYON_NUM_THREADS=1 $BIN infer 1 30 | tee -a "$OUT"
    RAYON_NUM_THREADS=1 $BIN infer-fast 1 30 | tee -a "$OUT"
    $PY infer 1 30 1 | tee -a "$OUT"
    RAYON_NUM_THREADS=1 $BIN infer 64 5 | tee -a "$OUT"
    RAYON_NUM_THREADS=1 $BIN infer-fast 64 5 | tee -a "$OUT"
    $PY infer 64 5 1 | tee -a "$OUT"
done
python3 bench-anchors/repr_table.py "$OUT"
