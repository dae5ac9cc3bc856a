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
T=${TRAVMAP:-target/release/travmap}
D=${DATA:-../shared/data}
OUT=${1:-crates/method/src/classifier}
# A fixed place, so that the models' record of their sources is the same every time.
work=target/embedded-model
mkdir -p "$work" "$OUT"
for rule in road offroad; do
    R="ground_truth.rule=\"$rule\""
    "$T" dataset -q -o "$work/$rule-semantickitti.parquet" --set "$R" \
        "$D/semantickitti-00/sequences/00" "$D/semantickitti-00-more/sequences/00" \
        "$D/semantickitti-07-000000/sequences/07" "$D/semantickitti-07-000964/sequences/07" \
        "$D/semantickitti-unknown-000850/sequences/00"
    "$T" dataset -q -o "$work/$rule-rellis3d.parquet" --set 'ground_truth.labels="rellis3d"' --set "$R" \
        "$D/rellis3d-000001/sequences/00" "$D/rellis3d-000104/sequences/00"
    "$T" dataset -q -o "$work/$rule-nuscenes.parquet" --set 'ground_truth.labels="nuscenes"' --set "$R" \
        "$D/nuscenes-lidarseg-scene-1072" "$D/nuscenes-lidarseg-scene-0002"
    "$T" train -q -o "$OUT/${rule}_model.json" --set "$R" \
        "$work/$rule-semantickitti.parquet" "$work/$rule-rellis3d.parquet" "$work/$rule-nuscenes.parquet"
done
