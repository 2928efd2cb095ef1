#!/usr/bin/env bash
# Sourced by scripts/test.sh: makes sure the other tools' own readers
# (PyPI `tensorboard` for event files, `safetensors` with NumPy for exported
# weights) are installed in the repository's own virtual environment, and
# sets INTEROP_VENV to it. learner/tests/interop.rs reads the learner's
# files with them.
TENSORBOARD_VERSION=2.18.0
SAFETENSORS_VERSION=0.4.5
INTEROP_VENV=.venv-interop
. "$(dirname "${BASH_SOURCE[0]}")/python-venv.sh"
python_venv "$INTEROP_VENV" "import tensorboard, safetensors.numpy" "tensorboard==$TENSORBOARD_VERSION" "safetensors==$SAFETENSORS_VERSION" numpy
