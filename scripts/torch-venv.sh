#!/usr/bin/env bash
# Sourced by scripts/test.sh and bench-anchors/repr-setup.sh: makes sure
# PyTorch is importable from the repository's own virtual environment
# (.venv-torch), with safetensors to load our exported weights into the
# PyTorch twin of the Full Model (bench-anchors/torch-repr), and sets
# TORCH_VENV to it. PyPI's Linux wheel brings its CUDA libraries (about
# 2.8 GB downloaded); the tests run it on the CPU.
TORCH_VERSION=2.15.0
TORCH_SAFETENSORS_VERSION=0.4.5
TORCH_VENV=.venv-torch
. "$(dirname "${BASH_SOURCE[0]}")/python-venv.sh"
python_venv "$TORCH_VENV" "import torch, safetensors.torch" \
    "torch==$TORCH_VERSION" "safetensors==$TORCH_SAFETENSORS_VERSION"
