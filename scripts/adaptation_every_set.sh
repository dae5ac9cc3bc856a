#!/usr/bin/env bash
# The positive-unlabelled study of docs/method.md ("Adaptation"): `eval --adapt`
# of every labelled set with the embedded model as prior, one row per way of
# learning the unknown cells; filtered mIoU, 12 m grid (about 3 minutes on 2 cores).
# Adaptation is unchecked here (adapt.check = false): the study compares learners.
#
#   scripts/adaptation_every_set.sh
#
# Needs ../shared/data; TRAVMAP names the binary.
set -euo pipefail
cd "$(dirname "$0")/.."
T=${TRAVMAP:-target/release/travmap}
D=${DATA:-../shared/data}
SETS=(
    "semantickitti-00/sequences/00 semantickitti road"
    "semantickitti-00-more/sequences/00 semantickitti road"
    "semantickitti-07-000000/sequences/07 semantickitti road"
    "semantickitti-07-000964/sequences/07 semantickitti road"
    "semantickitti-unknown-000850/sequences/00 semantickitti road"
    "rellis3d-000001/sequences/00 rellis3d road"
    "rellis3d-000001/sequences/00 rellis3d offroad"
    "rellis3d-000104/sequences/00 rellis3d road"
    "rellis3d-000104/sequences/00 rellis3d offroad"
    "nuscenes-lidarseg-scene-1072 nuscenes road"
    "nuscenes-lidarseg-scene-0002 nuscenes road"
    "nuscenes-lidarseg-scene-0002 nuscenes offroad"
)

# One row: its name, then the settings every set gets.
row() {
    local name=$1 cells=""
    shift
    for entry in "${SETS[@]}"; do
        read -r set labels rule <<<"$entry"
        cells+=" | $("$T" eval "$D/$set" --set "ground_truth.labels=\"$labels\"" \
            --set "ground_truth.rule=\"$rule\"" --set adapt.check=false --json -q "$@" 2>/dev/null | python3 -c '
import json, sys
print("%.1f" % (100 * json.loads(sys.stdin.readlines()[-1])["scores"]["miou"]))')"
    done
    echo "| $name$cells |"
}

echo "| mIoU | k00 | k00-more | k07-0000 | k07-0964 | k-unknown | R1 road | R1 off | R104 road | R104 off | n1072 road | n0002 road | n0002 off |"
echo "|---$(printf '|---%.0s' "${SETS[@]}")|"
row "prior (no adaptation)"
row "default (unknown cells not learnt from)" --adapt
for weight in 0.1 0.3 1; do
    row "unknown cells as negatives, weight $weight" --adapt --set adapt.unlabelled_weight=$weight
done
pu=(--set adapt.unlabelled_weight=1 --set adapt.negative_margin=1000 --set adapt.geometric_negatives=false)
row "footprint against everything else (biased SVM), sum" --adapt "${pu[@]}"
row "footprint against everything else, drive only" --adapt "${pu[@]}" --set 'adapt.learner="drive"'
