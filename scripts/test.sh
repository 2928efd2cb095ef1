#!/usr/bin/env bash
# The project's test command (README "Run the tests"; .ci/run calls exactly this).
# Installs what the tests need on a fresh Debian machine, then runs format,
# lint and every test of the workspace.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! command -v cargo >/dev/null 2>&1; then
    echo "error: cargo not found; install Rust with rustup (see README.md)" >&2
    exit 1
fi

# Pinocchio (PyPI `pin`) is the independent reference robot-model is checked
# against. It lives in a virtual environment inside the repository so that
# nothing is installed system-wide; the test fails rather than skips when it
# is missing here.
. scripts/pinocchio-venv.sh
export ROBOT_MODEL_PINOCCHIO_PYTHON="$PWD/$PINOCCHIO_VENV/bin/python"
export ROBOT_MODEL_REQUIRE_PINOCCHIO=1

# franky-sim (PyPI), a simulated FR3 speaking the robot's own protocol: the
# Franka backend's test runs the daemon against it (docs/franka.md), and
# fails rather than skips when it is missing here.
. scripts/franky-sim-venv.sh
export FRANKY_SIM_PYTHON="$PWD/$FRANKY_SIM_VENV/bin/python"
export FRANKY_SIM_REQUIRED=1

# TensorBoard and safetensors, whose own readers check the learner's event
# files and exported weights.
. scripts/interop-venv.sh
export INTEROP_PYTHON="$PWD/$INTEROP_VENV/bin/python"
export INTEROP_REQUIRED=1

# PyTorch, whose twin of the Full Model (bench-anchors/torch-repr) loads the
# exported representation and must compute the same z means.
. scripts/torch-venv.sh
export TORCH_PYTHON="$PWD/$TORCH_VENV/bin/python"
export TORCH_REQUIRED=1

echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy"
cargo clippy --workspace --all-targets --quiet -- -D warnings
echo "== cargo test"
cargo test --workspace

# Every benchmark and example the documents name runs here once in its quick
# mode, so that a documented command cannot rot unseen: a check that it runs
# (and that its own assertions hold), not a measurement. Debug builds,
# seconds each. Criterion benches run in criterion's test mode (each
# benchmark once); hw-sim's bench has the same convention.
echo "== benches and examples (quick mode)"
# With --workspace, and from the binaries `cargo test --workspace` already
# built, so that the workspace's one feature set is reused: a per-package
# `cargo test -p hw-sim --bench sim` resolves its own features and compiles
# the simulator's dependencies a second time.
cargo test --workspace --benches
target_dir="${CARGO_TARGET_DIR:-target}"
cargo build --workspace --examples --bins --quiet
quick_dir="$(mktemp -d)"
trap 'rm -rf "$quick_dir"' EXIT
"$target_dir/debug/examples/render_frames" "$quick_dir/frames" square
"$target_dir/debug/examples/fuzz_cycle" 200 1
"$target_dir/debug/robot-model" robot-model/urdf/panda.urdf --q "0 -0.3 0 -2 0 1.6 0.8" --frame peg_tip
"$target_dir/debug/examples/env_bench" --quick
# The representation's benchmarks: every convolution layer under each
# kernel choice, and a training step and both inference paths.
"$target_dir/debug/examples/conv_bench" --quick
"$target_dir/debug/examples/repr_bench" --quick
# The research probes are lab code (lab/probes/, a workspace of their own,
# built on demand), not run here.
# The timing harness for a second, without the real-time set-up (a check
# that it runs, not a measurement: docs/performance.md has the real one).
"$target_dir/debug/jitter" --duration-s 1 --no-realtime --out "$quick_dir/jitter"
