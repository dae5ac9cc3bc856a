#!/usr/bin/env bash
# The calibration study of docs/method.md ("A probability, not a vote"): for each
# rule, a model trained as the embedded one is without one scene, its P(traversable)
# on that scene's labelled cells (before the filter, 12 m grid) against the share
# that is traversable: the expected calibration error per held-out set, then the
# reliability table (tenths of P) pooled over every held-out set.
#
#   scripts/calibration_study.sh      # about 6 minutes on 2 cores
#
# Needs ../shared/data and jq; TRAVMAP names the binary, DATA the data; GRID_M the
# scored grid's side (default 12, the runs'; 36 is the training grid's).
set -euo pipefail
cd "$(dirname "$0")/.."
T=${TRAVMAP:-target/release/travmap}
D=${DATA:-../shared/data}
G=${GRID_M:-12}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# shellcheck source=labelled_sets.sh
source scripts/labelled_sets.sh

# A model trained under rule $1 on every set but scene $2's, into $3.
train_without() {
    local rule=$1 scene=$2 out=$3 tables=() paths
    for d in semantickitti rellis3d nuscenes; do
        paths=$(echo "$SETS" | awk -v d="$d" -v s="$scene" '$3 == d && $4 != s { print $2 }')
        [ -z "$paths" ] && continue
        # shellcheck disable=SC2086
        "$T" dataset -q -o "$work/$d.parquet" --set "$(labels "$d")" --set "ground_truth.rule=\"$rule\"" $paths 2>/dev/null
        tables+=("$work/$d.parquet")
    done
    "$T" train -q -o "$out" --set "ground_truth.rule=\"$rule\"" "${tables[@]}"
}

echo "| rule | held-out set | labelled cells | expected calibration error |"
echo "|---|---|---|---|"
: >"$work/bins"
for rule in road offroad; do
    for scene in 00 07 unknown rellis 1072 0002; do
        train_without "$rule" "$scene" "$work/model.json"
        while read -r name path dataset _; do
            "$T" eval "$path" --model "$work/model.json" --set "$(labels "$dataset")" \
                --set "ground_truth.rule=\"$rule\"" --set "grid.size_m=$G" --json -q 2>/dev/null | tail -n 1 >"$work/eval.json"
            jq -r --arg rule "$rule" --arg name "$name" \
                '"| \($rule) | \($name) | \(.calibration.cells) | \(.calibration.expected_calibration_error * 1000 | round / 1000) |"' "$work/eval.json"
            jq -r --arg rule "$rule" '.calibration.bins[] | "\($rule) \(.low) \(.cells) \(.mean_probability * .cells) \(.share_traversable * .cells)"' "$work/eval.json" >>"$work/bins"
        done < <(echo "$SETS" | awk -v s="$scene" '$4 == s')
    done
done
echo
echo "| rule | P | cells | mean P | share traversable |"
echo "|---|---|---|---|---|"
awk '{ key = $1 " " $2; cells[key] += $3; p[key] += $4; t[key] += $5 }
    END { for (k in cells) { split(k, f, " "); printf "| %s | %.1f-%.1f | %d | %.3f | %.3f |\n", f[1], f[2], f[2] + 0.1, cells[k], p[k] / cells[k], t[k] / cells[k] } }' \
    "$work/bins" | sort
