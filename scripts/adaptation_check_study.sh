#!/usr/bin/env bash
# The study of adaptation's check against its prior (docs/method.md, "Adaptation that
# never makes a map worse"): `eval --adapt` against the prior alone, filtered mIoU,
# 12 m grid, and whether the adapted model replaced the prior. Priors: the embedded
# model of each rule on every labelled set (in-sample); one scan of each labelled
# sequence alone, with the sequence's whole poses.txt (the footprint follows the
# real trajectory through one scan); models that never saw a dataset, on that
# dataset (where the prior is wrong and adaptation should help). About 3 minutes
# on 2 cores.
#
#   scripts/adaptation_check_study.sh
#
# Needs ../shared/data; TRAVMAP names the binary, DATA the data.
set -euo pipefail
cd "$(dirname "$0")/.."
T=${TRAVMAP:-target/release/travmap}
D=${DATA:-../shared/data}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# One row: the prior, the set, its labels and rule; the prior's and the adapted
# model's filtered mIoU, and the check's verdict.
row() {
    local prior=$1 name=$2 path=$3 labels=$4 rule=$5 settings
    settings=(--model "$prior" --set "ground_truth.labels=\"$labels\"" --set "ground_truth.rule=\"$rule\"" --json -q)
    local before after
    before=$("$T" eval "$path" "${settings[@]}" 2>/dev/null | tail -n 1 |
        jq -r '.scores.miou * 1000 | round / 10')
    after=$("$T" eval "$path" --adapt "${settings[@]}" 2>/dev/null | tail -n 1 |
        jq -r '(.scores.miou * 1000 | round / 10 | tostring) + "\t"
            + (.model.adaptation | (if .adapted then "adapted" else "kept" end) + "\t"
            + (if .prior_miou == null then (if (.why | test("guessed")) then "footprint guessed" else "too little evidence" end)
               else "\(.prior_miou * 1000 | round / 10) / \(.adapted_miou * 1000 | round / 10)" end)
            + "\t" + (if .confident_unknown > 0 then "\(.flipped_unknown * 1000 / .confident_unknown | round / 10) % of \(.confident_unknown)" else "" end))')
    IFS=$'\t' read -r adapted verdict check flipped <<<"$after"
    echo "| $(basename "$prior" .json) | $name | $rule | $before | $adapted | $verdict | $check | $flipped |"
}

echo "| prior | set | rule | prior mIoU | --adapt mIoU | check | evidence mIoU, prior / adapted | the prior's sure calls off the evidence, turned |"
echo "|---|---|---|---|---|---|---|---|"
# The embedded models on every labelled set, each under its own rule.
SETS="kitti-00 $D/semantickitti-00/sequences/00 semantickitti
kitti-00-more $D/semantickitti-00-more/sequences/00 semantickitti
kitti-07-0000 $D/semantickitti-07-000000/sequences/07 semantickitti
kitti-07-0964 $D/semantickitti-07-000964/sequences/07 semantickitti
kitti-unknown $D/semantickitti-unknown-000850/sequences/00 semantickitti
rellis-000001 $D/rellis3d-000001/sequences/00 rellis3d
rellis-000104 $D/rellis3d-000104/sequences/00 rellis3d
nuscenes-1072 $D/nuscenes-lidarseg-scene-1072 nuscenes
nuscenes-0002 $D/nuscenes-lidarseg-scene-0002 nuscenes"
for rule in road offroad; do
    while read -r name path labels; do
        row "$rule" "$name" "$path" "$labels" "$rule"
    done <<<"$SETS"
done

# One labelled scan alone with its sequence's whole poses.txt.
single() {
    local sequence=$1 frame=$2 out=$3
    mkdir -p "$out/velodyne" "$out/labels"
    for file in calib.txt poses.txt times.txt; do
        [ -e "$sequence/$file" ] && ln -s "$(realpath "$sequence/$file")" "$out/$file"
    done
    ln -s "$(realpath "$sequence/velodyne/$frame.bin")" "$out/velodyne/"
    ln -s "$(realpath "$sequence/labels/$frame.label")" "$out/labels/"
}
for entry in "semantickitti-00/sequences/00 000000" "semantickitti-00/sequences/00 000002" \
    "semantickitti-00-more/sequences/00 000052" "semantickitti-00-more/sequences/00 000088" "semantickitti-07-000000/sequences/07 000000" \
    "semantickitti-07-000000/sequences/07 000003"; do
    read -r sequence frame <<<"$entry"
    [ -e "$D/$sequence/labels/$frame.label" ] || continue
    out="$work/single-$(echo "$sequence" | cut -d/ -f1)-$frame"
    single "$D/$sequence" "$frame" "$out"
    for rule in road offroad; do
        row "$rule" "$(echo "$sequence" | cut -d/ -f1) scan $frame alone" "$out" semantickitti "$rule"
    done
done

# Models that never saw a dataset (trained as the embedded ones are, without it).
labels_of() { echo "ground_truth.labels=\"$1\""; }
for rule in road offroad; do
    for left_out in semantickitti rellis3d nuscenes; do
        tables=()
        for dataset in semantickitti rellis3d nuscenes; do
            [ "$dataset" = "$left_out" ] && continue
            paths=$(echo "$SETS" | awk -v d="$dataset" '$3 == d { print $2 }')
            # shellcheck disable=SC2086
            "$T" dataset -q -o "$work/$dataset.parquet" --set "$(labels_of "$dataset")" \
                --set "ground_truth.rule=\"$rule\"" $paths 2>/dev/null
            tables+=("$work/$dataset.parquet")
        done
        model="$work/without-$left_out-$rule.json"
        "$T" train -q -o "$model" --set "ground_truth.rule=\"$rule\"" "${tables[@]}" 2>/dev/null
        while read -r name path labels; do
            row "$model" "$name" "$path" "$labels" "$rule"
        done < <(echo "$SETS" | awk -v d="$left_out" '$3 == d')
    done
done
