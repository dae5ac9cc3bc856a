#!/usr/bin/env bash
# The embedded models, trained as shipped, one per rule of what is traversable:
# `road` (a car's road) and `offroad` (a robot that may also drive on grass, dirt and
# low vegetation). Each is trained on every labelled scan of ../shared/data under its
# rule, one cell table per dataset (each read with its own label ids), the three
# weighing alike in training (training.weigh_inputs = "equally").
#
#   scripts/train_embedded_model.sh        # writes crates/method/src/classifier/{road,offroad}_model.json
#   scripts/train_embedded_model.sh DIR    # writes DIR/road_model.json and DIR/offroad_model.json
#
# Deterministic: the same data gives the same models, bit for bit but the recorded
# training seconds (cargo test checks the shipped files against this script).
# TRAVMAP names the binary (default target/release/travmap), DATA the data.
set -euo pipefail
cd "$(dirname "$0")/.."
T=$(realpath "${TRAVMAP:-target/release/travmap}")
D=$(realpath "${DATA:-../shared/data}")
OUT=${1:-crates/method/src/classifier}
mkdir -p "$OUT"
OUT=$(realpath "$OUT")
# A fixed place, so that the models' record of their sources is the same every time;
# each model is trained from inside it, so that it names its datasets, not this folder.
work=target/embedded-model
for rule in road offroad; do
    R="ground_truth.rule=\"$rule\""
    mkdir -p "$work/$rule"
    (
        cd "$work/$rule"
        "$T" dataset -q -o semantickitti.parquet --set "$R" \
            "$D/semantickitti-00/sequences/00" "$D/semantickitti-00-more/sequences/00" \
            "$D/semantickitti-07-000000/sequences/07" "$D/semantickitti-07-000964/sequences/07" \
            "$D/semantickitti-unknown-000850/sequences/00"
        "$T" dataset -q -o rellis3d.parquet --set 'ground_truth.labels="rellis3d"' --set "$R" \
            "$D/rellis3d-000001/sequences/00" "$D/rellis3d-000104/sequences/00"
        "$T" dataset -q -o nuscenes.parquet --set 'ground_truth.labels="nuscenes"' --set "$R" \
            "$D/nuscenes-lidarseg-scene-1072" "$D/nuscenes-lidarseg-scene-0002"
        "$T" train -q -o "$OUT/${rule}_model.json" --set "$R" \
            semantickitti.parquet rellis3d.parquet nuscenes.parquet
    )
done
