#!/usr/bin/env bash
# How the representation's training step scales from one thread to two:
# ours (learner/examples/repr_bench.rs, the training convolution) and PyTorch
# (bench-anchors/torch-repr/bench.py, the same architecture), one Adam step
# of the Full Model at batch 64, 128×128 px, alternately, ROUNDS rounds, in
# one run. PyTorch is installed as for repr.sh (bench-anchors/repr-setup.sh).
# Results: docs/performance.md.
# Usage: bench-anchors/repr-threads.sh [ROUNDS] [OUT.jsonl]
set -euo pipefail
cd "$(dirname "$0")/.."
ROUNDS=${1:-3}
OUT=${2:-target/repr-threads.jsonl}
source bench-anchors/repr-setup.sh
: > "$OUT"
for r in $(seq 1 "$ROUNDS"); do
    echo "== round $r of $ROUNDS"
    for t in 1 2; do
        RAYON_NUM_THREADS=$t $BIN train 64 5 | tee -a "$OUT"
        $PY train 64 5 $t | tee -a "$OUT"
    done
done
python3 - "$OUT" <<'PY'
import json, sys, collections
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
by = collections.defaultdict(list)
for r in rows:
    by[(r["side"], r["threads"])].append(r["samples_per_s"])
print("| side | threads | median samples/s | range | rounds |")
print("|---|---|---|---|---|")
for k in sorted(by):
    v = sorted(by[k])
    print(f"| {k[0]} | {k[1]} | {v[len(v)//2]:.1f} | {v[0]:.1f}–{v[-1]:.1f} | {len(v)} |")
for side in sorted({k[0] for k in by}):
    a, b = sorted(by[(side, 1)]), sorted(by[(side, 2)])
    print(f"{side}: 2 threads / 1 thread = {b[len(b)//2] / a[len(a)//2]:.2f}")
PY
