#!/usr/bin/env bash
# Sourced by scripts/test.sh: makes sure franky-sim (PyPI, Apache-2.0: a
# MuJoCo-simulated Franka Research 3 that speaks the robot's own FCI
# protocol, docs/franka.md) is installed in the repository's own virtual
# environment, and sets FRANKY_SIM_VENV to it. The Franka backend's tests
# run the daemon against it through scripts/franky_sim_server.py.
FRANKY_SIM_VERSION=1.0.4
FRANKY_SIM_VENV=.venv-franky-sim
if ! "$FRANKY_SIM_VENV/bin/python" -c "import franky_sim" >/dev/null 2>&1; then
    echo "== installing franky-sim $FRANKY_SIM_VERSION into $FRANKY_SIM_VENV"
    if ! python3 -m venv "$FRANKY_SIM_VENV" >/dev/null 2>&1; then
        apt-get update -qq && apt-get install -y -qq python3-venv
        python3 -m venv "$FRANKY_SIM_VENV"
    fi
    "$FRANKY_SIM_VENV/bin/pip" install --quiet --disable-pip-version-check \
        "franky-sim==$FRANKY_SIM_VERSION"
fi
