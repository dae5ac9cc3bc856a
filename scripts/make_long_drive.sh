#!/usr/bin/env bash
# A long KITTI-layout drive for speed and memory figures (docs/speed.md): the six
# shipped scans of semantickitti-00 repeated along the first N poses of KITTI
# sequence 00 (kitti-odometry-meta), with KITTI object 000008's camera image as
# every frame's image_2 (appearance has a picture to read) and the sample's
# calib.txt. The scene repeats, so it is for timing, never for scores.
#   scripts/make_long_drive.sh 60 /tmp/d60    # then: travmap convert /tmp/d60 -o d60.mcap
set -euo pipefail
frames="${1:?frames (at most the 4541 poses of sequence 00)}"
out="${2:?output folder}"
data="$(cd "$(dirname "$0")/../../shared/data" && pwd)"
sample="$data/semantickitti-00/sequences/00"
meta="$data/kitti-odometry-meta/sequences/00"
image="$data/kitti-object-000008/training/image_2/000008.png"
mkdir -p "$out/velodyne" "$out/image_2"
for ((i = 0; i < frames; i++)); do
    name=$(printf %06d "$i")
    ln -f "$sample/velodyne/$(printf %06d $((i % 6))).bin" "$out/velodyne/$name.bin" 2>/dev/null ||
        cp "$sample/velodyne/$(printf %06d $((i % 6))).bin" "$out/velodyne/$name.bin"
    ln -f "$image" "$out/image_2/$name.png" 2>/dev/null || cp "$image" "$out/image_2/$name.png"
done
cp "$sample/calib.txt" "$out/"
head -n "$frames" "$meta/poses.txt" >"$out/poses.txt"
head -n "$frames" "$meta/times.txt" >"$out/times.txt"
echo "$out: $frames frames"
