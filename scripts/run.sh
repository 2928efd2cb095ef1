#!/usr/bin/env bash
# The main command: builds the stack (release) and runs it on the simulator:
# hw-sim, rt-controller and the policy node as separate processes, a few
# insertion episodes of the default peg, each episode's outcome and MCAP log
# printed, everything stopped cleanly (Ctrl-C included).
# Arguments go to `learner stack` (see `--help`), e.g. --peg hexagon --episodes 5.
set -euo pipefail
cd "$(dirname "$0")/.."
# Cargo's own progress is shown: a first build takes minutes, and a silent
# terminal for that long looks hung.
echo "run.sh: building hw-sim, rt-controller and learner (release; the first build takes several minutes)" >&2
cargo build --release -p hw-sim -p rt-controller -p learner --bins
# Where cargo put them: CARGO_TARGET_DIR when set (relative to this root).
target_dir="${CARGO_TARGET_DIR:-target}"
echo "run.sh: starting the stack" >&2
exec "$target_dir/release/learner" stack "$@"
