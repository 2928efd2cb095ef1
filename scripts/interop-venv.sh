#!/usr/bin/env bash
# Sourced by scripts/test.sh: makes sure the other tools' own readers
# (PyPI `tensorboard` for event files, `safetensors` with NumPy for exported
# weights) are installed in the repository's own virtual environment, and
# sets INTEROP_VENV to it. learner/tests/interop.rs reads the learner's
# files with them.
TENSORBOARD_VERSION=2.18.0
SAFETENSORS_VERSION=0.4.5
INTEROP_VENV=.venv-interop
if ! "$INTEROP_VENV/bin/python" -c "import tensorboard, safetensors.numpy" >/dev/null 2>&1; then
    echo "== installing tensorboard $TENSORBOARD_VERSION and safetensors $SAFETENSORS_VERSION into $INTEROP_VENV"
    if ! python3 -m venv "$INTEROP_VENV" >/dev/null 2>&1; then
        apt-get update -qq && apt-get install -y -qq python3-venv
        python3 -m venv "$INTEROP_VENV"
    fi
    "$INTEROP_VENV/bin/pip" install --quiet --disable-pip-version-check \
        "tensorboard==$TENSORBOARD_VERSION" "safetensors==$SAFETENSORS_VERSION" numpy
fi
