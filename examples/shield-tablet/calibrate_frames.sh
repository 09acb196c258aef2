#!/usr/bin/env bash
# Self-calibrate the Shield-tablet capture from its photos: frames 0002-0006 together, starting
# from the published values (focal length 1558.69 px, no time offset) and the proper rotation
# `YXz` next to the published, improper axis matrix. Writes ./shield-out/calibrated.json (the
# corrected capture of frame 2) and prints every parameter before and after.
# Usage (from this folder): ./calibrate_frames.sh [extra gyrodeblur calibrate options]
set -euo pipefail
data=../../../shared/data/real/shield-tablet
mkdir -p shield-out
photos=()
captures=()
while read -r frame start; do
  sed -e "s/\"exposure_start\": [0-9.]*/\"exposure_start\": $start/" \
      -e 's/"fx": 2010.0, "fy": 2010.0/"fx": 1558.69, "fy": 1558.69/' \
      -e 's/"orientation": "yxz"/"orientation": "YXz"/' \
      -e 's/"time_offset": 0.0176/"time_offset": 0.0/' \
      -e 's#"path": "../../../shared#"path": "../../../../shared#' \
      capture_0003.json > "shield-out/published_$frame.json"
  photos+=("$data/$frame.jpg")
  captures+=(--capture "shield-out/published_$frame.json")
done < <(./frames_in_log.sh)
gyrodeblur calibrate "${photos[@]}" "${captures[@]}" -o shield-out/calibrated.json --overwrite "$@"
