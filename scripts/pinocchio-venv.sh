#!/usr/bin/env bash
# Sourced by scripts/test.sh and bench-anchors/run.sh: makes sure Pinocchio
# (PyPI `pin`, the reference robot-model is checked and timed against) is
# importable from the repository's own virtual environment, and sets
# PINOCCHIO_VENV to it. Nothing is installed system-wide except, on a bare
# Debian, the python3-venv package.
PIN_VERSION=4.1.0
PINOCCHIO_VENV=.venv-pinocchio
. "$(dirname "${BASH_SOURCE[0]}")/python-venv.sh"
python_venv "$PINOCCHIO_VENV" "import pinocchio" "pin==$PIN_VERSION"
