#!/usr/bin/env bash
# Sourced by scripts/test.sh: makes sure TensorBoard (PyPI `tensorboard`) is
# installed in the repository's own virtual environment, and sets
# TENSORBOARD_VENV to it. The learner's test of its event files reads them
# with TensorBoard's own reader (tests/runlog.rs).
TENSORBOARD_VERSION=2.18.0
TENSORBOARD_VENV=.venv-tensorboard
if ! "$TENSORBOARD_VENV/bin/python" -c "import tensorboard" >/dev/null 2>&1; then
    echo "== installing tensorboard $TENSORBOARD_VERSION into $TENSORBOARD_VENV"
    if ! python3 -m venv "$TENSORBOARD_VENV" >/dev/null 2>&1; then
        apt-get update -qq && apt-get install -y -qq python3-venv
        python3 -m venv "$TENSORBOARD_VENV"
    fi
    "$TENSORBOARD_VENV/bin/pip" install --quiet --disable-pip-version-check \
        "tensorboard==$TENSORBOARD_VERSION"
fi
