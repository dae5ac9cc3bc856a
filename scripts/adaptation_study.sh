#!/usr/bin/env bash
# The adaptation study of docs/method.md ("Adaptation"): each row is a way to adapt,
# each column a scene the prior never saw, mIoU (Acc / TNR in the second table)
# after the filter, 12 m and 40 m grids.
#
#   scripts/adaptation_study.sh            # every row (about 5 minutes on 2 cores)
#   scripts/adaptation_study.sh --quick    # the prior and the default
#
# Columns: seq 00 frames 0-2 (prior trained on seq 07 only), seq 07 frame 964
# (prior trained on seq 00 only), RELLIS-3D 000104 with the off-road and the road
# rule (prior: the embedded road model). Adaptation is unchecked here
# (adapt.check = false): the study compares learners, not the check. Needs
# ../shared/data; TRAVMAP names the binary.
set -euo pipefail
cd "$(dirname "$0")/.."
T=${TRAVMAP:-target/release/travmap}
D=${DATA:-../shared/data}
S00=$D/semantickitti-00/sequences/00
S07=$D/semantickitti-07-000964/sequences/07
R=$D/rellis3d-000104/sequences/00
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$T" train "$S07" -o "$work/prior07.json" -q
"$T" train "$S00" -o "$work/prior00.json" -q
# The priors again with each scan's remission scaled to KITTI's 95th percentile,
# and the embedded model's training likewise (for RELLIS-3D).
p95=(--set 'features.remission_scale="scan_p95"')
if [ "${1:-}" != "--quick" ]; then
    "$T" train "$S07" -o "$work/prior07-p95.json" -q "${p95[@]}"
    "$T" train "$S00" -o "$work/prior00-p95.json" -q "${p95[@]}"
    "$T" train "$S00" "$S07" -o "$work/embedded-p95.json" -q "${p95[@]}"
fi

# Prints "Acc/mIoU/TNR" of one eval.
score() {
    "$T" eval "$@" --set adapt.check=false --json 2>/dev/null | python3 -c '
import json, sys
for line in sys.stdin:
    d = json.loads(line)
    if d.get("type") == "summary":
        s = d["scores"]
        print("%.1f/%.1f/%.1f" % (100 * s["accuracy"], 100 * s["miou"], 100 * s["tnr"]))'
}

# One row: its name, then the settings (and --adapt) every column gets; the priors'
# file names end in $SUFFIX (RELLIS-3D's prior is the embedded model unless $EMBEDDED).
row() {
    local name=$1
    shift
    local cells=() rellis=()
    [ -n "${EMBEDDED:-}" ] && rellis=(--model "$EMBEDDED")
    for grid in 12 40; do
        local g=(--set "grid.size_m=$grid")
        cells+=("$(score "$S00" --frames 0..3 --model "$work/prior07${SUFFIX:-}.json" "${g[@]}" "$@")")
        cells+=("$(score "$S07" --model "$work/prior00${SUFFIX:-}.json" "${g[@]}" "$@")")
        cells+=("$(score "$R" "${rellis[@]}" --set 'ground_truth.labels="rellis3d"' --set 'ground_truth.rule="offroad"' "${g[@]}" "$@")")
        cells+=("$(score "$R" "${rellis[@]}" --set 'ground_truth.labels="rellis3d"' "${g[@]}" "$@")")
    done
    echo "$name|${cells[*]}"
}

rows() {
    row "prior (no adaptation)"
    row "default: sum, C 1, gamma 0.02, prior weight 0.75, margin 2, horizon 10 m" --adapt
    [ "${1:-}" = "--quick" ] && return
    row "drive only" --adapt --set 'adapt.learner="drive"'
    row "drive and prior cells, weight 0.75" --adapt --set 'adapt.learner="drive_and_prior"'
    row "sum, prior weight 0.5" --adapt --set adapt.prior_weight=0.5
    row "sum, prior weight 1" --adapt --set adapt.prior_weight=1
    row "sum, C 10, gamma 0.05" --adapt --set adapt.c=10 --set adapt.gamma=0.05
    row "+ 1 self-training round" --adapt --set adapt.rounds=1
    row "horizon 20 m" --adapt --set adapt.horizon_m=20
    row "negatives at margin 1" --adapt --set adapt.negative_margin=1
    row "negatives at margin 3" --adapt --set adapt.negative_margin=3
    row "no geometric negatives" --adapt --set adapt.geometric_negatives=false
    row "prior, foreign remission to the fallback" --set 'classifier.foreign_remission="fallback"'
    row "default, foreign remission to the fallback" --adapt --set 'classifier.foreign_remission="fallback"'
    SUFFIX=-p95 EMBEDDED="$work/embedded-p95.json" row "prior, remission scaled to p95" "${p95[@]}"
    SUFFIX=-p95 EMBEDDED="$work/embedded-p95.json" row "default, remission scaled to p95" --adapt "${p95[@]}"
}

rows "$@" | python3 -c '
import sys
names = ["00 @12", "07 @12", "R off @12", "R road @12", "00 @40", "07 @40", "R off @40", "R road @40"]
rows = [line.rstrip("\n").split("|") for line in sys.stdin]
cells = [(name, [c.split("/") for c in row.split()]) for name, row in rows]
print("| mIoU | " + " | ".join(names) + " | mean | change |")
print("|---" * (len(names) + 3) + "|")
prior = None
for name, values in cells:
    mious = [float(v[1]) for v in values]
    mean = sum(mious) / len(mious)
    prior = mean if prior is None else prior
    print("| %s | %s | %.2f | %+.2f |" % (name, " | ".join("%.1f" % m for m in mious), mean, mean - prior))
print()
print("| Acc / TNR | " + " | ".join(names) + " |")
print("|---" * (len(names) + 1) + "|")
for name, values in cells[:2]:
    print("| %s | %s |" % (name, " | ".join("%s / %s" % (v[0], v[2]) for v in values)))
'
