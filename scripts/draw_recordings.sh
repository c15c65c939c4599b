#!/usr/bin/env bash
# What the daemon publishes on each room-scale recording, drawn over its depth cloud:
# docs/images/published-NAME.png, and the list of published objects (Markdown, standard
# output) that BENCHMARKS.md quotes. Each recording plays looped at its recorded rate for
# SECONDS (default 20) while `tacmesh subscribe --out` keeps the latest meshes.
#
#   scripts/draw_recordings.sh [NAME...]     # names: oni bag tum slambook pcl_kinect milk
#
# Needs a release build (cargo build --release) and a Python with numpy and matplotlib
# (PYTHON, default python3).
set -euo pipefail
cd "$(dirname "$0")/.."
tacmesh=target/release/tacmesh
python="${PYTHON:-python3}"
seconds="${SECONDS_PER_RECORDING:-20}"
declare -A spec=(
  [oni]="replay:testdata/recordings/openni1_primesense_12frames_640x480.oni"
  [bag]="replay:testdata/recordings/realsense_d435_single_depth_color_640x480.bag"
  [tum]="replay:testdata/depth/tum_fr1?fx=520.9&fy=521.0&cx=325.1&cy=249.7&depth_scale_m=0.0002"
  [slambook]="replay:testdata/depth/slambook_kinect?fx=518&fy=519&cx=325.5&cy=253.5"
  [pcl_kinect]="replay:testdata/depth/pcl_kinect_grabber?fx=525&fy=525&cx=320&cy=240"
  [milk]="replay:testdata/pointclouds/pcl/milk_cartoon_all_small_clorox.pcd"
)
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(oni bag tum slambook pcl_kinect milk)
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p docs/images
for name in "${names[@]}"; do
  s="${spec[$name]:?unknown recording $name}"
  mkdir -p "$work/$name/cloud" "$work/$name/meshes"
  "$tacmesh" capture --sensor "$s" --out "$work/$name/cloud" 2>/dev/null
  "$tacmesh" run --sensor "$s" --loop --socket "$work/$name.sock" --duration-s "$seconds" \
    2>"$work/$name.log" &
  daemon=$!
  while [ ! -S "$work/$name.sock" ]; do sleep 0.1; done
  "$tacmesh" subscribe --socket "$work/$name.sock" --out "$work/$name/meshes" >/dev/null || true
  wait "$daemon"
  echo "### $name ($s, ${seconds} s)"
  echo
  grep "frames in" "$work/$name.log" | tail -1 | sed 's/.*frames in/frames in/; s/; frame-to-publish.*//'
  echo
  "$python" scripts/draw_scene.py "$work/$name/cloud/frame-0.ply" "$work/$name/meshes" \
    --title "$name: published meshes over the depth cloud (${seconds} s)" \
    -o "docs/images/published-$name.png"
  echo
done
