#!/usr/bin/env bash
# The main command: builds the stack (release) and runs it on the simulator:
# hw-sim, rt-controller and the policy node as separate processes, a few
# insertion episodes of the default peg, each episode's outcome and MCAP log
# printed, everything stopped cleanly (Ctrl-C included).
# Arguments go to `policy-node stack` (see `--help`), e.g. --peg hexagon --episodes 5.
# Only what the stack runs is built: hw-sim, rt-controller and the node
# (learner-node, without the training stack). --policy takes a deployed
# policy (`learner policy export`); given a training run's checkpoint.json
# instead, the training toolkit is built too and `learner stack` converts it.
#
# --robot franky-sim runs the same three-process path against franky-sim, a
# simulated Franka FR3 (docs/franka.md, "The whole stack on franky-sim"):
# installs it (scripts/franky-sim-venv.sh) and, without --hole-pos, gives the
# example calibration below (franky-sim has no box).
set -euo pipefail
cd "$(dirname "$0")/.."
franky=0
hole=0
policy=
prev=
for arg in "$@"; do
    case "$prev/$arg" in
        --robot/franky-sim | */--robot=franky-sim) franky=1 ;;
        */--hole-pos | */--hole-pos=*) hole=1 ;;
        */--franky-sim-python | */--franky-sim-python=*) python_given=1 ;;
        --policy/*) policy="$arg" ;;
        */--policy=*) policy="${arg#--policy=}" ;;
    esac
    prev="$arg"
done
# A deployed policy names its format; anything else is a training checkpoint.
node_pkg=learner-node
node_bin=policy-node
if [ -n "$policy" ] && ! grep -q '"format": *"learner-node/policy"' "$policy" 2>/dev/null; then
    node_pkg=learner
    node_bin=learner
fi
extra=()
if [ "$franky" = 1 ]; then
    . scripts/franky-sim-venv.sh
    if [ "${python_given:-0}" = 0 ]; then
        extra+=(--franky-sim-python "$PWD/$FRANKY_SIM_VENV/bin/python")
    fi
    if [ "$hole" = 0 ]; then
        # 5 cm in front of and 10 cm below the FR3's start pose, on the
        # arm's centre line (docs/franka.md says why there).
        echo "run.sh: no --hole-pos given; using the example calibration 0.60,0.0,0.42" >&2
        extra+=(--hole-pos 0.60,0.0,0.42)
    fi
fi
# Cargo's own progress is shown: a first build takes minutes, and a silent
# terminal for that long looks hung.
echo "run.sh: building hw-sim, rt-controller and $node_pkg (release; the first build takes minutes)" >&2
cargo build --release -p hw-sim -p rt-controller-daemon -p "$node_pkg" --bins
# Where cargo put them: CARGO_TARGET_DIR when set (relative to this root).
target_dir="${CARGO_TARGET_DIR:-target}"
echo "run.sh: starting the stack" >&2
exec "$target_dir/release/$node_bin" stack "$@" "${extra[@]}"
