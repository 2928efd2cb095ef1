# Sourced by the representation benchmarks (repr.sh, repr-threads.sh): PyTorch
# from PyPI into .venv-torch (a benchmark anchor, not a dependency), our bench
# binary built; sets BIN and PY.
TORCH_VERSION=2.15.0
VENV=.venv-torch
if ! "$VENV/bin/python" -c "import torch" >/dev/null 2>&1; then
    echo "== installing torch $TORCH_VERSION into $VENV"
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install --quiet --disable-pip-version-check "torch==$TORCH_VERSION"
fi
cargo build --release --quiet -p learner --example repr_bench
BIN=target/release/examples/repr_bench
PY="$VENV/bin/python bench-anchors/torch-repr/bench.py"
