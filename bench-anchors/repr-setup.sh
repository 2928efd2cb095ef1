# Sourced by the representation benchmarks (repr.sh, repr-threads.sh): PyTorch
# from PyPI into .venv-torch (a benchmark anchor, not a dependency), our bench
# binary built; sets BIN and PY.
. scripts/torch-venv.sh
VENV="$TORCH_VENV"
cargo build --release --quiet -p learner --example repr_bench
BIN=target/release/examples/repr_bench
PY="$VENV/bin/python bench-anchors/torch-repr/bench.py"
