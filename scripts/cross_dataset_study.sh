#!/usr/bin/env bash
# The cross-dataset study of docs/method.md ("Streets and sensors it has never
# seen"): models trained as the embedded one is (road rule, one cell table per
# dataset, the datasets weighing alike), each without some of the labelled scans,
# and scored on those it left out (filtered mIoU, 12 m grid), beside the label-free
# fit each drive reports (the share of its cells within the model's margin, and
# whether that says the fit is poor); last, the rank correlation of the two over
# every pair.
#
#   scripts/cross_dataset_study.sh      # both tables (about 15 minutes on 2 cores)
#
# Leave one scene out: SemanticKITTI sequence 00 (two sets), 07 (two sets), the scan
# of unknown sequence, RELLIS-3D (its two scans are of one place), nuScenes scene
# 1072, scene 0002. Leave one dataset out: SemanticKITTI, RELLIS-3D, nuScenes.
# Needs ../shared/data; TRAVMAP names the binary, DATA the data; SETTINGS adds
# settings to every command, e.g.
#   SETTINGS='--set features.groups=["remission","frame_relative"]' scripts/cross_dataset_study.sh
set -euo pipefail
cd "$(dirname "$0")/.."
T=${TRAVMAP:-target/release/travmap}
D=${DATA:-../shared/data}
read -ra settings <<<"${SETTINGS:-}"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# shellcheck source=labelled_sets.sh
source scripts/labelled_sets.sh

# Trains on every set whose scene and dataset differ from $1 and $2 (a blank
# matches nothing), one cell table per dataset, into $3.
train_without() {
    local scene=$1 dataset=$2 out=$3 tables=()
    for d in semantickitti rellis3d nuscenes; do
        [ "$d" = "$dataset" ] && continue
        local paths
        paths=$(echo "$SETS" | awk -v d="$d" -v s="$scene" '$3 == d && $4 != s { print $2 }')
        [ -z "$paths" ] && continue
        # shellcheck disable=SC2086
        "$T" dataset -q -o "$work/$d.parquet" --set "$(labels "$d")" "${settings[@]}" $paths
        tables+=("$work/$d.parquet")
    done
    "$T" train -q -o "$out" "${settings[@]}" "${tables[@]}"
}

# Prints the filtered mIoU of set $1 under the model $2, the share of its cells
# within the model's margin, and whether the fit is poor, as table cells; and
# keeps the pair for the correlation.
score() {
    local path dataset
    path=$(echo "$SETS" | awk -v n="$1" '$1 == n { print $2 }')
    dataset=$(echo "$SETS" | awk -v n="$1" '$1 == n { print $3 }')
    "$T" eval "$path" --model "$2" --set "$(labels "$dataset")" "${settings[@]}" --json 2>/dev/null |
        jq -r 'select(.type == "summary")
            | "\(.scores.miou * 100) \(.fit.unsure_share * 100) \(.fit.poor)"' |
        tee -a "$work/pairs" |
        awk '{ printf "%.1f | %.1f %% | %s", $1, $2, ($3 == "true" ? "poor" : "") }'
}

echo "| held out | set | mIoU | cells within the margin | fit |"
echo "|---|---|---|---|---|"
for scene in 00 07 unknown rellis 1072 0002; do
    train_without "$scene" "" "$work/model.json"
    for name in $(echo "$SETS" | awk -v s="$scene" '$4 == s { print $1 }'); do
        echo "| scene $scene | $name | $(score "$name" "$work/model.json") |"
    done
done
for dataset in semantickitti rellis3d nuscenes; do
    train_without "" "$dataset" "$work/model.json"
    for name in $(echo "$SETS" | awk -v d="$dataset" '$3 == d { print $1 }'); do
        echo "| dataset $dataset | $name | $(score "$name" "$work/model.json") |"
    done
done

# Spearman's rank correlation of mIoU and the share within the margin (ties share
# their mean rank); and the pairs the notice missed or fired on wrongly.
python3 - "$work/pairs" <<'PY'
import sys
pairs = [tuple(map(float, line.split()[:2])) + (line.split()[2] == "true",) for line in open(sys.argv[1])]
def ranks(values):
    order = sorted(range(len(values)), key=lambda i: values[i])
    rank = [0.0] * len(values)
    i = 0
    while i < len(order):
        j = i
        while j + 1 < len(order) and values[order[j + 1]] == values[order[i]]:
            j += 1
        for k in range(i, j + 1):
            rank[order[k]] = (i + j) / 2 + 1
        i = j + 1
    return rank
a, b = ranks([p[0] for p in pairs]), ranks([p[1] for p in pairs])
n = len(pairs)
ma, mb = sum(a) / n, sum(b) / n
cov = sum((x - ma) * (y - mb) for x, y in zip(a, b))
rho = cov / (sum((x - ma) ** 2 for x in a) * sum((y - mb) ** 2 for y in b)) ** 0.5
missed = sum(1 for m, _, poor in pairs if m < 60 and not poor)
wrong = sum(1 for m, _, poor in pairs if m > 85 and poor)
print(f"\nSpearman's rho of mIoU and the share within the margin over {n} pairs: {rho:.2f}; "
      f"pairs below 60 the notice missed: {missed} of {sum(1 for m, _, _ in pairs if m < 60)}; "
      f"pairs above 85 it fired on: {wrong} of {sum(1 for m, _, _ in pairs if m > 85)}")
PY
