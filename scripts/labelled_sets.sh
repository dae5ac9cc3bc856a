# The shipped labelled sets, a line each: name, path, dataset (its label ids) and
# scene (sets of one scene are held out together). Sourced by the studies; D is the
# data folder.
# shellcheck shell=bash disable=SC2034
SETS="kitti-00 $D/semantickitti-00/sequences/00 semantickitti 00
kitti-00-more $D/semantickitti-00-more/sequences/00 semantickitti 00
kitti-07-0000 $D/semantickitti-07-000000/sequences/07 semantickitti 07
kitti-07-0964 $D/semantickitti-07-000964/sequences/07 semantickitti 07
kitti-unknown $D/semantickitti-unknown-000850/sequences/00 semantickitti unknown
rellis-000001 $D/rellis3d-000001/sequences/00 rellis3d rellis
rellis-000104 $D/rellis3d-000104/sequences/00 rellis3d rellis
nuscenes-1072 $D/nuscenes-lidarseg-scene-1072 nuscenes 1072
nuscenes-0002 $D/nuscenes-lidarseg-scene-0002 nuscenes 0002"

# The setting that reads dataset $1's label ids.
labels() { echo "ground_truth.labels=\"$1\""; }
