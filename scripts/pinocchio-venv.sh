#!/usr/bin/env bash
# Sourced by scripts/test.sh and bench-anchors/run.sh: makes sure Pinocchio
# (PyPI `pin`, the reference robot-model is checked and timed against) is
# importable from the repository's own virtual environment, and sets
# PINOCCHIO_VENV to it. Nothing is installed system-wide except, on a bare
# Debian, the python3-venv package.
PIN_VERSION=4.1.0
PINOCCHIO_VENV=.venv-pinocchio
if ! "$PINOCCHIO_VENV/bin/python" -c "import pinocchio" >/dev/null 2>&1; then
    echo "== installing Pinocchio $PIN_VERSION into $PINOCCHIO_VENV"
    if ! python3 -m venv "$PINOCCHIO_VENV" >/dev/null 2>&1; then
        apt-get update -qq && apt-get install -y -qq python3-venv
        python3 -m venv "$PINOCCHIO_VENV"
    fi
    "$PINOCCHIO_VENV/bin/pip" install --quiet --disable-pip-version-check "pin==$PIN_VERSION"
fi
