#!/usr/bin/env bash
# Sourced by scripts/test.sh: makes sure franky-sim (PyPI, Apache-2.0: a
# MuJoCo-simulated Franka Research 3 that speaks the robot's own FCI
# protocol, docs/franka.md) is installed in the repository's own virtual
# environment, and sets FRANKY_SIM_VENV to it. The Franka backend's tests
# run the daemon against it through scripts/franky_sim_server.py.
FRANKY_SIM_VERSION=1.0.4
FRANKY_SIM_VENV=.venv-franky-sim
. "$(dirname "${BASH_SOURCE[0]}")/python-venv.sh"
python_venv "$FRANKY_SIM_VENV" "import franky_sim" "franky-sim==$FRANKY_SIM_VERSION"
