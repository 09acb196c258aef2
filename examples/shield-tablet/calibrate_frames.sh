#!/usr/bin/env bash
# Self-calibrate the Shield-tablet capture from its photos: frames 0002-0006 together, starting
# from the published values (focal length 1558.69 px, no time offset) and the proper rotation
# `YXz` next to the published, improper axis matrix. Writes ./shield-out/calibrated.json (the
# corrected capture of frame 2) and prints every parameter before and after.
# Usage (from any folder; the outputs go to this one): ./calibrate_frames.sh [extra gyrodeblur calibrate options]
set -euo pipefail
. "$(dirname "$0")/shared_data.sh"      # cd here; $data: the capture's folder
frames=$(./frames_in_log.sh)
mkdir -p shield-out
photos=()
captures=()
while read -r frame start; do
  python3 - "$start" "shield-out/published_$frame.json" "$data" <<'PY'
import json, os, sys
start, out, data = float(sys.argv[1]), sys.argv[2], sys.argv[3]
cap = json.load(open("capture_0003.json"))
cap["exposure_start"] = start
cap["camera"].update(fx=1558.69, fy=1558.69)          # the published focal length
cap["gyro"].update(orientation="YXz", time_offset=0.0,  # the log where $data says it is
                   path=os.path.abspath(os.path.join(data, "sensor_events.txt")))
json.dump(cap, open(out, "w"), indent=2)
PY
  photos+=("$data/$frame.jpg")
  captures+=(--capture "shield-out/published_$frame.json")
done <<< "$frames"
gyrodeblur calibrate "${photos[@]}" "${captures[@]}" -o shield-out/calibrated.json --overwrite "$@"
