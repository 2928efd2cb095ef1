#!/usr/bin/env bash
# The main command: builds the stack (release) and runs it on the simulator:
# hw-sim, rt-controller and the policy node as separate processes, a few
# insertion episodes of the default peg, each episode's outcome and MCAP log
# printed, everything stopped cleanly (Ctrl-C included).
# Arguments go to `learner stack` (see `--help`), e.g. --peg hexagon --episodes 5.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet -p hw-sim -p rt-controller -p learner --bins
exec target/release/learner stack "$@"
