#!/usr/bin/env bash
# Sourced by scripts/test.sh: makes sure the other tools' own readers
# (PyPI `tensorboard` for event files, `safetensors` with NumPy for exported
# weights, `mcap` with `mcap-ros2-support` for logs and `jsonschema` to check
# their JSON channels against their own schemas, `h5py` to write files in
# the authors' HDF5 layout, `websockets` as a Foxglove WebSocket client of the
# live stack) are installed in the
# repository's own virtual environment, and sets INTEROP_VENV to it. learner/tests/interop.rs reads the learner's
# files with them.
TENSORBOARD_VERSION=2.18.0
SAFETENSORS_VERSION=0.4.5
MCAP_VERSION=1.6.0
MCAP_ROS2_VERSION=0.6.0
H5PY_VERSION=3.16.0
JSONSCHEMA_VERSION=4.23.0
WEBSOCKETS_VERSION=15.0.1
INTEROP_VENV=.venv-interop
. "$(dirname "${BASH_SOURCE[0]}")/python-venv.sh"
python_venv "$INTEROP_VENV" "import tensorboard, safetensors.numpy, mcap_ros2.decoder, h5py, jsonschema, websockets" \
    "tensorboard==$TENSORBOARD_VERSION" "safetensors==$SAFETENSORS_VERSION" numpy \
    "mcap==$MCAP_VERSION" "mcap-ros2-support==$MCAP_ROS2_VERSION" "h5py==$H5PY_VERSION" \
    "jsonschema==$JSONSCHEMA_VERSION" "websockets==$WEBSOCKETS_VERSION"
