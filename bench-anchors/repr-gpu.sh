#!/usr/bin/env bash
# The representation on an NVIDIA GPU: ours (learner/examples/repr_bench.rs on
# burn's Vulkan backend, built with `--features vulkan`) against PyTorch on
# CUDA running the same architecture (bench-anchors/torch-repr/bench.py),
# alternately, ROUNDS rounds, in one run on one machine: one Adam step of the
# Full Model at batch 64, 128×128 px; the z means at batch 1 and 64.
#
# The GPU machine has no Rust toolchain and no network: build the bench binary
# elsewhere and pass its path; PyTorch is the machine's own `python3`.
#   cargo build --release -p learner --features vulkan --example repr_bench
# Usage: bench-anchors/repr-gpu.sh REPR_BENCH_BINARY [ROUNDS] [OUT.jsonl]
# Results: docs/performance.md, "The representation on an NVIDIA GPU".
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${1:?usage: bench-anchors/repr-gpu.sh REPR_BENCH_BINARY [ROUNDS] [OUT.jsonl]}
ROUNDS=${2:-2}
OUT=${3:-target/repr-gpu.jsonl}
PY="python3 bench-anchors/torch-repr/bench.py"
mkdir -p "$(dirname "$OUT")"
: > "$OUT"
for r in $(seq 1 "$ROUNDS"); do
    echo "== round $r of $ROUNDS"
    REPR_BENCH_DEVICE=vulkan $BIN train 64 10 | tee -a "$OUT"
    $PY train 64 10 4 cuda | tee -a "$OUT"
    REPR_BENCH_DEVICE=vulkan $BIN infer 1 30 | tee -a "$OUT"
    $PY infer 1 30 4 cuda | tee -a "$OUT"
    REPR_BENCH_DEVICE=vulkan $BIN infer 64 10 | tee -a "$OUT"
    $PY infer 64 10 4 cuda | tee -a "$OUT"
done
python3 bench-anchors/repr_table.py "$OUT"
