#!/usr/bin/env bash
# Measures robot-model and its two anchors (Pinocchio C++, dynibo) on the
# Panda in one session, on this machine, and prints their medians side by
# side. See bench-anchors/README.md; results go into docs/performance.md.
set -euo pipefail
cd "$(dirname "$0")/.."
URDF="$PWD/robot-model/urdf/panda.urdf"
mkdir -p bench-anchors/build

# Pinocchio's headers and libraries ship in its PyPI wheels; Eigen's and
# urdfdom's headers in cmeel-eigen and cmeel-urdfdom-headers.
. scripts/pinocchio-venv.sh
"$PINOCCHIO_VENV/bin/pip" install --quiet --disable-pip-version-check "cmeel-eigen==3.4.1" "cmeel-urdfdom-headers==3.0.0"
PREFIX=$(ls -d "$PINOCCHIO_VENV"/lib/python3*/site-packages/cmeel.prefix)
echo "== building the Pinocchio anchor (g++ -O3, same ISA baseline as rustc's default)"
# The definitions are those Pinocchio's CMake targets export; the algorithms
# are compiled header-only here (no PINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION),
# as Pinocchio's own benchmarks do.
g++ -O3 -DNDEBUG -std=c++17 -w \
    -DBOOST_MPL_LIMIT_LIST_SIZE=30 -DBOOST_MPL_LIMIT_VECTOR_SIZE=30 -DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS \
    -DBOOST_FUSION_INVOKE_MAX_ARITY=12 -DPINOCCHIO_WITH_URDFDOM -DPINOCCHIO_URDFDOM_HEADERS_MAJOR_VERSION=3 \
    -DPINOCCHIO_URDFDOM_HEADERS_MINOR_VERSION=0 -DPINOCCHIO_URDFDOM_HEADERS_PATCH_VERSION=0 \
    -I"$PREFIX/include" -I"$PREFIX/include/eigen3" -I"$PREFIX/include/urdfdom_headers" \
    bench-anchors/pinocchio/bench.cpp -o bench-anchors/build/pinocchio-anchor \
    -L"$PREFIX/lib" -Wl,-rpath,"$PREFIX/lib" -lpinocchio_parsers -lpinocchio_default \
    -lurdfdom_model -lboost_filesystem -lboost_serialization
echo "== building the dynibo anchor"
cargo build --quiet --release --manifest-path bench-anchors/dynibo/Cargo.toml --target-dir bench-anchors/target

echo "== running (anchors, robot-model, anchors again: the spread shows the machine's noise)"
bench-anchors/build/pinocchio-anchor "$URDF"
bench-anchors/target/release/dynibo-anchor "$URDF"
cargo bench --quiet -p robot-model --bench dynamics -- --noplot >/dev/null 2>&1 || cargo bench -p robot-model --bench dynamics
printf 'robot-model (criterion median ns/call):'
for op in fk fk+jacobian jdot_v crba rnea gravity forward_dynamics coriolis_matrix; do
    f="target/criterion/panda/$op/new/estimates.json"
    printf ' %s %s ' "$op" "$(python3 -c "import json,sys; print(round(json.load(open(sys.argv[1]))['median']['point_estimate']))" "$f")"
done
echo
bench-anchors/build/pinocchio-anchor "$URDF"
bench-anchors/target/release/dynibo-anchor "$URDF"
