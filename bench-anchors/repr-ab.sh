#!/usr/bin/env bash
# Two builds of our training step and PyTorch's, alternately, the three
# sides' order rotating each round: is a change faster, and where does each
# build stand against PyTorch in the same rounds?
#   OLD, NEW: repr_bench binaries (e.g. copies of target/release/examples/
#   repr_bench built at two commits); THREADS and BATCH as in repr.sh's
#   training (2 and 64; 1 and 32 for the one-thread step).
# Usage: bench-anchors/repr-ab.sh OLD NEW [ROUNDS] [THREADS] [BATCH] [OUT.jsonl]
# Then: python3 bench-anchors/repr_ab_table.py OUT.jsonl
set -euo pipefail
cd "$(dirname "$0")/.."
OLD=$1 NEW=$2 ROUNDS=${3:-10} THREADS=${4:-2} BATCH=${5:-64}
OUT=${6:-target/repr-ab.jsonl}
STEPS=5
[ "$BATCH" -le 32 ] && STEPS=4
source bench-anchors/repr-setup.sh
: > "$OUT"
for r in $(seq 1 "$ROUNDS"); do
    case $((r % 3)) in
        0) order="old new torch" ;;
        1) order="new torch old" ;;
        2) order="torch old new" ;;
    esac
    echo "== round $r of $ROUNDS: $order"
    for side in $order; do
        case $side in
            old) line=$(RAYON_NUM_THREADS=$THREADS "$OLD" train "$BATCH" "$STEPS") ;;
            new) line=$(RAYON_NUM_THREADS=$THREADS "$NEW" train "$BATCH" "$STEPS") ;;
            torch) line=$($PY train "$BATCH" "$STEPS" "$THREADS" 2>/dev/null) ;;
        esac
        echo "{\"round\": $r, \"bin\": \"$side\", \"at\": \"$(date -u +%FT%TZ)\", ${line#\{}" | tee -a "$OUT"
    done
done
python3 bench-anchors/repr_ab_table.py "$OUT"
