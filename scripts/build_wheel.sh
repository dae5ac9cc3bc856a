#!/usr/bin/env bash
# Builds the wheel into target/wheels: the `travmap` command (release) as the
# wheel's script and the Python module around crates/python. Needs maturin
# (`pip install maturin`); MATURIN names another one.
set -euo pipefail
cd "$(dirname "$0")/.."
maturin="${MATURIN:-maturin}"
cargo build --release --bin travmap
rm -rf target/wheel-data
mkdir -p target/wheel-data/scripts
cp target/release/travmap target/wheel-data/scripts/travmap
rm -f target/wheels/travmap-*.whl
"$maturin" build --release --out target/wheels --quiet
ls target/wheels/travmap-*.whl
