#!/usr/bin/env bash
# The embedded model, trained as shipped: every labelled scan of ../shared/data under
# the road rule, one cell table per dataset (each read with its own label ids), the
# three weighing alike in training (training.weigh_inputs = "equally").
#
#   scripts/train_embedded_model.sh        # writes crates/method/src/classifier/default_model.json
#   scripts/train_embedded_model.sh OUT    # writes OUT instead
#
# Deterministic: the same data gives the same model, bit for bit but the recorded
# training seconds (cargo test checks the shipped file against this script).
# TRAVMAP names the binary (default target/release/travmap), DATA the data.
set -euo pipefail
cd "$(dirname "$0")/.."
T=${TRAVMAP:-target/release/travmap}
D=${DATA:-../shared/data}
OUT=${1:-crates/method/src/classifier/default_model.json}
# A fixed place, so that the model's record of its sources is the same every time.
work=target/embedded-model
mkdir -p "$work"
"$T" dataset -q -o "$work/semantickitti.parquet" \
    "$D/semantickitti-00/sequences/00" "$D/semantickitti-00-more/sequences/00" \
    "$D/semantickitti-07-000000/sequences/07" "$D/semantickitti-07-000964/sequences/07" \
    "$D/semantickitti-unknown-000850/sequences/00"
"$T" dataset -q -o "$work/rellis3d.parquet" --set 'ground_truth.labels="rellis3d"' \
    "$D/rellis3d-000001/sequences/00" "$D/rellis3d-000104/sequences/00"
"$T" dataset -q -o "$work/nuscenes.parquet" --set 'ground_truth.labels="nuscenes"' \
    "$D/nuscenes-lidarseg-scene-1072" "$D/nuscenes-lidarseg-scene-0002"
"$T" train -q -o "$OUT" "$work/semantickitti.parquet" "$work/rellis3d.parquet" "$work/nuscenes.parquet"
