#!/usr/bin/env bash
# Copies what `learner experiment --config configs/experiments/ablations_near.toml`
# wrote for finished variants into this folder: the experiment's results,
# charts and stage log, and per variant its evaluation, the DAgger's table
# and curves and the representation's metrics.
# The stage log here keeps every variant's lines: a run on a fresh checkout
# (its runs/ empty but for restore_results.py's results.json) logs only its
# own, so those are appended rather than copied over.
# Usage (from the repository root): lab/notebook/experiments/ablations-near/copy_variant.sh VARIANT...
set -euo pipefail
run=runs/experiments/ablations_near
here=lab/notebook/experiments/ablations-near
[ $# -gt 0 ] || { echo "usage: $0 VARIANT..." >&2; exit 2; }
for v in "$@"; do
  [ -f "$run/$v/eval-square.json" ] || { echo "$run/$v: no evaluation yet" >&2; exit 1; }
done
cp "$run"/results.md "$run"/results.csv "$run"/completed-*.png "$here"/
for v in "$@"; do
  mkdir -p "$here/$v"
  # Only lines not yet here, so running it twice appends nothing (awk has
  # read the log here whole before it appends to it).
  if [ -f "$run/stages.log" ]; then
    touch "$here/stages.log"
    awk -v p="$v: " 'FILENAME == ARGV[1] { seen[$0] = 1; next }
      index($0, p) == 1 && !seen[$0]++' "$here/stages.log" "$run/stages.log" >> "$here/stages.log"
  fi
  cp "$run/$v"/eval-*.json "$here/$v"/
  cp "$run/$v"/policy/{distill.csv,distill.png,distill-error.png} "$here/$v"/
  if [ -f "$run/$v/repr/metrics.csv" ]; then cp "$run/$v/repr/metrics.csv" "$here/$v"/; fi
done
