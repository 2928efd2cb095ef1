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

echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy"
cargo clippy --workspace --all-targets --quiet -- -D warnings
echo "== cargo test"
cargo test --workspace
