#!/usr/bin/env bash
# The labelling study of docs/method.md ("Teaching it a robot"): for each dataset held
# out, a prior trained as the embedded model is (road rule) on the other two
# datasets; then K cells of one scene of the held-out dataset asked by
# `travmap label` (by the prior's margin, or at random), answered from that scene's
# ground truth as a perfect labeller would (`--answers-from-ground-truth`), learnt
# with the prior's support vectors (`train --prior`), and scored on the held-out
# dataset's other scenes (filtered mIoU, 12 m grid, their mean).
#
#   scripts/labelling_study.sh             # the table (about 4 minutes on 2 cores)
#
# Labelled scene -> scored scenes: SemanticKITTI sequence 07 (four scans) -> sequence
# 00 (two sets) and the scan of unknown sequence; RELLIS-3D 000001 -> 000104;
# nuScenes scene 0002 -> scene 1072. Asking at random is the mean over SEEDS seeds.
# Needs ../shared/data and jq; TRAVMAP names the binary, DATA the data, ASKS the
# budgets (default "25 100 400"), SEEDS the random seeds (default "0 1 2"); SETTINGS
# adds settings to every command, e.g. SETTINGS='--set training.taught_weight=10', and
# ASKING flags to every `label`, e.g. ASKING='--ask-spacing 4'.
set -euo pipefail
cd "$(dirname "$0")/.."
T=${TRAVMAP:-target/release/travmap}
D=${DATA:-../shared/data}
read -ra asks <<<"${ASKS:-25 100 400}"
read -ra seeds <<<"${SEEDS:-0 1 2}"
read -ra settings <<<"${SETTINGS:-}"
read -ra asking <<<"${ASKING:-}"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# dataset labelled-scene scored-scenes...
DATASETS="semantickitti $D/semantickitti-07-000000/sequences/07 $D/semantickitti-00/sequences/00 $D/semantickitti-00-more/sequences/00 $D/semantickitti-unknown-000850/sequences/00
rellis3d $D/rellis3d-000001/sequences/00 $D/rellis3d-000104/sequences/00
nuscenes $D/nuscenes-lidarseg-scene-0002 $D/nuscenes-lidarseg-scene-1072"
ALL="semantickitti $D/semantickitti-00/sequences/00 $D/semantickitti-00-more/sequences/00 $D/semantickitti-07-000000/sequences/07 $D/semantickitti-07-000964/sequences/07 $D/semantickitti-unknown-000850/sequences/00
rellis3d $D/rellis3d-000001/sequences/00 $D/rellis3d-000104/sequences/00
nuscenes $D/nuscenes-lidarseg-scene-1072 $D/nuscenes-lidarseg-scene-0002"

labels() { echo "ground_truth.labels=\"$1\""; }

# A prior trained without dataset $1, into $2: one cell table per other dataset.
prior_without() {
    local tables=() other paths
    while read -r other paths; do
        [ "$other" = "$1" ] && continue
        # shellcheck disable=SC2086
        "$T" dataset -q -o "$work/$other.parquet" --set "$(labels "$other")" "${settings[@]}" $paths 2>/dev/null
        tables+=("$work/$other.parquet")
    done <<<"$ALL"
    "$T" train -q -o "$2" "${settings[@]}" "${tables[@]}"
}

# The mean filtered mIoU (percent) of model $1 over the scenes $3... of dataset $2.
score() {
    local model=$1 dataset=$2 total=0 n=0 miou
    shift 2
    for scene in "$@"; do
        miou=$("$T" eval "$scene" --model "$model" --set "$(labels "$dataset")" "${settings[@]}" --json 2>/dev/null |
            jq -r 'select(.type == "summary") | .scores.miou * 100')
        total=$(echo "$total + $miou" | bc -l)
        n=$((n + 1))
    done
    echo "scale=1; $total / $n" | bc -l
}

# Model $1 taught with $2 cells of scene $3 (dataset $4) asked by $5 (margin, or a
# seed for random), into $6.
taught() {
    local prior=$1 ask=$2 scene=$3 dataset=$4 by=$5 out=$6 how=(--ask-by margin)
    [ "$by" != margin ] && how=(--ask-by random --seed "$by")
    "$T" label "$scene" -q -o "$work/labels.parquet" --model "$prior" --ask "$ask" "${how[@]}" \
        --answers-from-ground-truth --set "$(labels "$dataset")" "${settings[@]}" "${asking[@]}"
    "$T" train "$work/labels.parquet" -q --prior "$prior" -o "$out" --set "$(labels "$dataset")" "${settings[@]}"
    rm -f "$work/labels.parquet"
}

header="| held out (labelled scene) | asked by | 0 |"
rule="|---|---|---|"
for ask in "${asks[@]}"; do
    header+=" $ask |"
    rule+="---|"
done
echo "$header"
echo "$rule"
while read -r dataset labelled scored; do
    # shellcheck disable=SC2086
    set -- $scored
    prior_without "$dataset" "$work/prior.json"
    none=$(score "$work/prior.json" "$dataset" "$@")
    scene=${labelled#"$D"/}
    row="| $dataset (${scene%%/*}) | the model's margin | $none |"
    random_row="| | random (mean of ${#seeds[@]} seeds) | $none |"
    for ask in "${asks[@]}"; do
        taught "$work/prior.json" "$ask" "$labelled" "$dataset" margin "$work/m.json"
        row+=" $(score "$work/m.json" "$dataset" "$@") |"
        total=0
        for seed in "${seeds[@]}"; do
            taught "$work/prior.json" "$ask" "$labelled" "$dataset" "$seed" "$work/m.json"
            total=$(echo "$total + $(score "$work/m.json" "$dataset" "$@")" | bc -l)
        done
        random_row+=" $(echo "scale=1; $total / ${#seeds[@]}" | bc -l) |"
    done
    echo "$row"
    echo "$random_row"
done <<<"$DATASETS"
